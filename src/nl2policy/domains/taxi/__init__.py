"""The taxi domain (spec.toml): a shift of driving between an airport, a village and a city,
with an exact model (env.py) and exact searches for its ceilings (ceilings.py)."""
