"""The comparison with LeRobot's stock policies: ``omnid-benchmark`` (plan, run, report), the main job
``omnid-demo`` and the open-loop diagnostic ``omnid-offline-eval``, built on the real console commands."""
