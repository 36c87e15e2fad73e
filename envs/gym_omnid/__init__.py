"""Multi-view MuJoCo benchmark envs."""
