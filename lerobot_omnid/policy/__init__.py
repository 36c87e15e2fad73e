"""The OmniD policy: ``configuration_omnid``, ``modeling_omnid`` and ``processor_omnid`` side by side (LeRobot
finds the model and processors from the config's module path), and the parts of the model."""
