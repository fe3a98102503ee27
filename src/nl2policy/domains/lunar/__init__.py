"""The lunar domain (spec.toml): Gymnasium's LunarLander-v3 with discrete engines, its
observation read as it is, and Gymnasium's own heuristic lander as a yardstick (heuristic.py)."""
