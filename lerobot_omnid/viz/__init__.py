"""``omnid-viz``: what OmniD sees (anchors and samples on each camera, the bird's-eye plane)."""
