"""Names of LeRobot features, built on LeRobot's own constants."""

from __future__ import annotations

from lerobot.utils.constants import OBS_IMAGE, OBS_IMAGES

IMAGE_KEY_PREFIX = f"{OBS_IMAGES}."


def image_key(camera: str) -> str:
    """``cam_b`` -> ``observation.images.cam_b``; full feature keys are returned unchanged."""
    return camera if camera.startswith(OBS_IMAGE) else IMAGE_KEY_PREFIX + camera


def camera_name(key: str) -> str:
    """``observation.images.cam_b`` -> ``cam_b``; bare names are returned unchanged."""
    return key.removeprefix(IMAGE_KEY_PREFIX)
