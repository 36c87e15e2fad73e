"""OmniD for LeRobot."""
