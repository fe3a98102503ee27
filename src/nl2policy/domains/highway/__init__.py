"""The highway domain (spec.toml): highway-env's three-lane road seen through six features
(env.py), and a vectorized twin of the same scene that trains faster (twin.py, vec.py)."""
