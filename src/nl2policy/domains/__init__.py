"""The two domains, each a declarative spec (``<name>.toml`` + the corpus vocabulary) and a
registered Gymnasium env whose observation is the spec's feature vector."""

from __future__ import annotations

from functools import lru_cache

import gymnasium as gym

from nl2policy.domains.spec import Domain, load_domain

DOMAINS = ("taxi", "highway")

_ENTRY_POINTS = {
    "nl2policy/Taxi-v0": "nl2policy.domains.taxi:TaxiEnv",
    "nl2policy/Highway-v0": "nl2policy.domains.highway:HighwayFeatures",
}
for _env_id, _entry in _ENTRY_POINTS.items():
    if _env_id not in gym.registry:
        gym.register(_env_id, entry_point=_entry)
# highway-env's scene, vectorized: one episode with gym.make, N with gym.make_vec.
if "nl2policy/HighwayTwin-v0" not in gym.registry:
    gym.register("nl2policy/HighwayTwin-v0", entry_point="nl2policy.domains.highway_vec:HighwayTwinEnv",
                 vector_entry_point="nl2policy.domains.highway_vec:HighwayTwinVectorEnv")


@lru_cache(maxsize=None)
def get_domain(name: str) -> Domain:
    """The domain called `name` ("taxi" or "highway"); a clear KeyError otherwise."""
    if name not in DOMAINS:
        raise KeyError(f"unknown domain {name!r}; choose one of: {', '.join(DOMAINS)}")
    return load_domain(name)


def make_env(name: str, **kwargs) -> gym.Env:
    return gym.make(get_domain(name).env_id, **kwargs)


__all__ = ["DOMAINS", "Domain", "get_domain", "make_env"]
