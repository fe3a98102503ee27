"""The exact taxi model as arrays, for scoring many stationary feature policies at once.

``taxi.expected_return`` walks the model one state at a time (about 0.1 s a policy): right
for one tree, too slow for an exhaustive search over millions. The model has a structure
that arrays exploit: what follows an action in a state does not depend on the tick, except
that a trip ending after the shift earns nothing and ends the episode. So with the 24
*feature states* (place, passenger, traffic, village wait; the policy sees exactly these)
the model is three tables built once from ``TaxiModel.outcomes``:

* ``ticks[s, a]``: how long action ``a`` takes in feature state ``s`` (it depends on the
  traffic at departure, which is part of ``s``);
* ``reward[s, a]``: the fare earned if the trip ends by the end of the shift;
* ``next_prob[s, a, s']``: where it leads.

and the value of a policy at tick ``t`` is ``Q[t, s, a] = [t + ticks <= T] (reward +
next_prob . V[t + ticks])`` with ``V = 0`` from the end of the shift on: the same backward
induction as ``taxi._backward``, vectorized over policies (agreement to 1e-9 is tested).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from typing import Callable

import numpy as np

from .env import AIRPORT, CITY, VILLAGE, WAIT, TaxiModel, TaxiState

N_ACTIONS = 4


def feature_states() -> list[TaxiState]:
    """The 24 feature states at tick 0, in a fixed order (place, passenger, traffic, wait)."""
    return [TaxiState(place, passenger, heavy, long_wait, 0)
            for place in (AIRPORT, VILLAGE, CITY) for passenger in (False, True)
            for heavy in (False, True) for long_wait in (False, True)]


def effective_action(state: TaxiState, action: int) -> int:
    """Driving to where the taxi already is counts as waiting (``TaxiModel.outcomes``): the
    two are one action, and searches count them once."""
    return WAIT if action == state.place else action


@dataclass(frozen=True, eq=False)  # compared and hashed by identity (it holds arrays)
class TaxiTables:
    model: TaxiModel
    states: tuple[TaxiState, ...]
    ticks: np.ndarray = field(repr=False)  # (S, A) int
    reward: np.ndarray = field(repr=False)  # (S, A)
    next_prob: np.ndarray = field(repr=False)  # (S, A, S)
    initial: np.ndarray = field(repr=False)  # (S,)

    @property
    def n_states(self) -> int:
        return len(self.states)

    def features(self) -> np.ndarray:
        """The policy's input for every feature state, shape (S, 6)."""
        return np.stack([s.features() for s in self.states])

    def reachable(self) -> list[int]:
        """Feature states some policy can reach from the start (closure under every action).
        A policy's action elsewhere never affects its return."""
        seen = {int(i) for i in np.flatnonzero(self.initial)}
        frontier = list(seen)
        while frontier:
            s = frontier.pop()
            for nxt in np.flatnonzero(self.next_prob[s].sum(axis=0)):
                if int(nxt) not in seen:
                    seen.add(int(nxt))
                    frontier.append(int(nxt))
        return sorted(seen)

    def returns(self, policies: np.ndarray) -> np.ndarray:
        """Exact expected return of each stationary policy, ``policies`` shape (P, S) of
        action indices (``best_returns`` with one action allowed, four times cheaper)."""
        policies = np.asarray(policies, dtype=np.int64)
        n, horizon, longest = len(policies), self.model.shift_ticks, int(self.ticks.max())
        states = np.arange(self.n_states)
        ticks = self.ticks[states, policies]  # (P, S)
        reward, next_prob = self.reward[states, policies], self.next_prob[states, policies]  # (P, S), (P, S, S)
        values = np.zeros((n, horizon + longest + 1, self.n_states))
        rows = np.arange(n)[:, None]
        for t in range(horizon - 1, -1, -1):
            q = reward + np.einsum("psk,psk->ps", next_prob, values[rows, t + ticks, :])
            values[:, t, :] = np.where(t + ticks <= horizon, q, 0.0)
        return values[:, 0, :] @ self.initial

    def best_returns(self, allowed: np.ndarray) -> np.ndarray:
        """For each mask ``allowed`` (P, S, A), the optimum over policies that may see the
        tick and in state s take any allowed action: with one action allowed per state, the
        return of that stationary policy; with more, an upper bound on every stationary
        policy that picks among them (each is one of the policies maximised over)."""
        allowed = np.asarray(allowed, dtype=bool)
        return self._backward(len(allowed), lambda q: np.where(allowed, q, -np.inf).max(axis=2))

    def mixed_returns(self, probs: np.ndarray) -> np.ndarray:
        """Exact expected return of each stochastic stationary policy, ``probs`` (P, S, A) the
        probability of each action in each feature state (a soft DDT acting by sampling)."""
        probs = np.asarray(probs, dtype=np.float64)
        return self._backward(len(probs), lambda q: (probs * q).sum(axis=2))

    def _backward(self, n: int, value_of: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
        """Backward induction for `n` policies at once; `value_of` turns Q (n, S, A) at a
        tick into V (n, S)."""
        horizon, longest = self.model.shift_ticks, int(self.ticks.max())
        values = np.zeros((n, horizon + longest + 1, self.n_states))
        states = np.arange(self.n_states)
        for t in range(horizon - 1, -1, -1):
            future = values[:, t + self.ticks, :]  # (P, S, A, S): V at each action's arrival tick
            q = self.reward + np.einsum("sak,psak->psa", self.next_prob, future)
            q = np.where(t + self.ticks <= horizon, q, 0.0)
            values[:, t, states] = value_of(q)
        return values[:, 0, :] @ self.initial


@lru_cache(maxsize=4)
def taxi_tables(model: TaxiModel = TaxiModel()) -> TaxiTables:
    states = feature_states()
    index = {s: i for i, s in enumerate(states)}
    n = len(states)
    ticks = np.zeros((n, N_ACTIONS), dtype=np.int64)
    reward = np.zeros((n, N_ACTIONS))
    next_prob = np.zeros((n, N_ACTIONS, n))
    for i, s in enumerate(states):
        for a in range(N_ACTIONS):
            dest = s.place if a == WAIT else a
            ticks[i, a] = model.trip_ticks(s.place, dest, s.heavy)
            for o in model.outcomes(s, a):  # tick 0: every trip ends within the shift
                reward[i, a] += o.prob * o.reward
                next_prob[i, a, index[o.state._replace(tick=0)]] += o.prob
    initial = np.zeros(n)
    for p, s in model.initial_states():
        initial[index[s]] += p
    return TaxiTables(model, tuple(states), ticks, reward, next_prob, initial)


__all__ = ["TaxiTables", "effective_action", "feature_states", "taxi_tables"]
