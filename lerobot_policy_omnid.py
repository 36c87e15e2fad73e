import lerobot_omnid  # noqa: F401  (registers the omnid policy and env configs)
