"""The taxi domain: a shift of driving between an airport, a village and a city.

Dynamics (one tick is five minutes; a shift is ``shift_ticks`` ticks)
----------------------------------------------------------------------
* **State**: where the taxi is (airport, village or city; it decides only when it is at a
  place), whether it carries a passenger, whether the road to the city is jammed
  (``heavy_traffic``), whether passengers at the village are slow to show up
  (``long_wait``), and the tick of the shift. The policy sees all but the tick.
* **Traffic and the village wait** are two independent two-state Markov chains that move
  every tick: heavy traffic starts with probability ``p_jam`` and clears with ``p_unjam``;
  a long wait starts with ``p_slow`` and ends with ``p_fast``. The taxi starts the shift at
  the airport, empty, with both chains drawn from their stationary distributions.
* **Actions**: drive to the airport, village or city, or wait. Driving to where the taxi
  already is counts as waiting. A wait lasts one tick. A trip lasts ``village_ticks``
  between airport and village, and ``city_ticks_clear`` or ``city_ticks_jammed`` when it
  uses the road to the city (either end in the city), by the traffic at departure.
* **Passengers**: every passenger wants the airport. An empty taxi arriving in (or waiting
  in) the city always takes a passenger; at the village one boards with probability
  ``p_board_short`` or ``p_board_long`` per arrival or wait, by the wait state at that
  moment; nobody boards at the airport. A passenger who is driven anywhere but the airport,
  or made to wait, gets out and takes another cab: the fare is lost, and nobody else
  boards during that same step.
* **Reward**: +1 for each passenger delivered to the airport. The episode ends when the
  shift is over; a trip still under way then earns nothing.

Scale (exact expectations under the defaults, from ``expected_return``): a uniformly random
policy earns about 1.5 fares a shift; "airport if I have a passenger, else the city unless it
is jammed, then the village" earns about 7.9; the optimum, about 8.4 (``optimal_policy``: backward
induction on this exact model, tick included) is the ceiling. The defaults were picked by a
small search for that scale in which the long village wait matters when the city is jammed.

One function, ``TaxiModel.outcomes``, defines the dynamics as an explicit distribution.
The env samples from it and the dynamic programme sums over it, so the optimum is the
optimum of the very env that policies are trained in.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Callable, NamedTuple, Optional

import gymnasium as gym
import numpy as np
from gymnasium import spaces

AIRPORT, VILLAGE, CITY = 0, 1, 2
PLACES = ("airport", "village", "city")
GO_AIRPORT, GO_VILLAGE, GO_CITY, WAIT = 0, 1, 2, 3


class TaxiState(NamedTuple):
    place: int
    passenger: bool
    heavy: bool
    long_wait: bool
    tick: int

    def features(self) -> np.ndarray:
        """The policy's input, in the order of spec.toml's ``features``."""
        x = np.zeros(6, dtype=np.float32)
        x[self.place] = 1.0
        x[3], x[4], x[5] = float(self.passenger), float(self.heavy), float(self.long_wait)
        return x


class Outcome(NamedTuple):
    prob: float
    state: TaxiState
    reward: float
    done: bool


@dataclass(frozen=True)
class TaxiModel:
    shift_ticks: int = 90
    city_ticks_clear: int = 3
    city_ticks_jammed: int = 15
    village_ticks: int = 5
    p_jam: float = 0.1
    p_unjam: float = 0.1
    p_slow: float = 0.1
    p_fast: float = 0.05
    p_board_short: float = 0.9
    p_board_long: float = 0.03

    def _chain(self, p_on: float, p_off: float, ticks: int) -> np.ndarray:
        step = np.array([[1 - p_on, p_on], [p_off, 1 - p_off]])
        return np.linalg.matrix_power(step, ticks)

    def stationary(self, p_on: float, p_off: float) -> float:
        """Long-run probability that a chain is in its 'on' state."""
        return p_on / (p_on + p_off)

    def initial_states(self) -> list[tuple[float, TaxiState]]:
        ph = self.stationary(self.p_jam, self.p_unjam)
        pl = self.stationary(self.p_slow, self.p_fast)
        return [
            ((ph if h else 1 - ph) * (pl if w else 1 - pl), TaxiState(AIRPORT, False, h, w, 0))
            for h in (False, True)
            for w in (False, True)
        ]

    def trip_ticks(self, origin: int, dest: int, heavy: bool) -> int:
        if origin == dest:
            return 1
        if CITY in (origin, dest):
            return self.city_ticks_jammed if heavy else self.city_ticks_clear
        return self.village_ticks

    def outcomes(self, s: TaxiState, action: int) -> list[Outcome]:
        """The exact distribution of what follows taking `action` in state `s`."""
        dest = s.place if action == WAIT else action
        ticks = self.trip_ticks(s.place, dest, s.heavy)
        passenger = s.passenger and dest == AIRPORT and s.place != AIRPORT
        tick = s.tick + ticks
        traffic = self._chain(self.p_jam, self.p_unjam, ticks)[int(s.heavy)]
        wait = self._chain(self.p_slow, self.p_fast, ticks)[int(s.long_wait)]
        out: list[Outcome] = []
        for h in (False, True):
            for w in (False, True):
                p = traffic[int(h)] * wait[int(w)]
                if p == 0.0:
                    continue
                if tick > self.shift_ticks:  # the shift ends mid-trip: nothing earned
                    out.append(Outcome(p, TaxiState(dest, passenger, h, w, self.shift_ticks), 0.0, True))
                    continue
                done = tick >= self.shift_ticks
                if dest == AIRPORT and passenger:
                    out.append(Outcome(p, TaxiState(dest, False, h, w, tick), 1.0, done))
                elif dest == CITY and not s.passenger:
                    out.append(Outcome(p, TaxiState(dest, True, h, w, tick), 0.0, done))
                elif dest == VILLAGE and not s.passenger:
                    board = self.p_board_long if w else self.p_board_short
                    out.append(Outcome(p * board, TaxiState(dest, True, h, w, tick), 0.0, done))
                    out.append(Outcome(p * (1 - board), TaxiState(dest, False, h, w, tick), 0.0, done))
                else:
                    out.append(Outcome(p, TaxiState(dest, passenger, h, w, tick), 0.0, done))
        return out


class TaxiEnv(gym.Env):
    """Gymnasium env over `TaxiModel`; one step is one decision (a wait or a whole trip)."""

    metadata = {"render_modes": ["ansi"], "render_fps": 4}

    def __init__(self, model: Optional[TaxiModel] = None, render_mode: Optional[str] = None) -> None:
        self.model = model or TaxiModel()
        self.render_mode = render_mode
        self.observation_space = spaces.Box(0.0, 1.0, shape=(6,), dtype=np.float32)
        self.action_space = spaces.Discrete(4)
        self.state: Optional[TaxiState] = None
        self.fares = 0

    def reset(self, *, seed: Optional[int] = None, options: Optional[dict] = None):
        super().reset(seed=seed)
        self.state = self._sample(self.model.initial_states())
        self.fares = 0
        return self.state.features(), self._info()

    def step(self, action):
        if self.state is None:
            raise RuntimeError("call reset() before step()")
        outcome = self._sample([(o.prob, o) for o in self.model.outcomes(self.state, int(action))])
        self.state = outcome.state
        self.fares += int(outcome.reward)
        return self.state.features(), outcome.reward, outcome.done, False, self._info()

    def _sample(self, weighted: list):
        probs = np.array([w for w, _ in weighted])
        return weighted[self.np_random.choice(len(weighted), p=probs / probs.sum())][1]

    def _info(self) -> dict:
        return {"tick": self.state.tick, "fares": self.fares}

    def render(self) -> Optional[str]:
        if self.render_mode != "ansi" or self.state is None:
            return None
        s = self.state
        return (
            f"tick {s.tick:2d}/{self.model.shift_ticks} at {PLACES[s.place]:7s} "
            f"passenger={'yes' if s.passenger else 'no '} traffic={'heavy' if s.heavy else 'light'} "
            f"village wait={'long' if s.long_wait else 'short'} fares={self.fares}"
        )


Policy = Callable[[TaxiState], int]


def _all_states(model: TaxiModel, tick: int):
    for place in (AIRPORT, VILLAGE, CITY):
        for passenger in (False, True):
            for h in (False, True):
                for w in (False, True):
                    yield TaxiState(place, passenger, h, w, tick)


def _backward(model: TaxiModel, choose: Optional[Policy]) -> tuple[float, dict[TaxiState, int]]:
    """Backward induction over ticks. With `choose` None, maximises (value iteration on the
    finite-horizon model); otherwise evaluates that stationary policy exactly."""
    values: dict[TaxiState, float] = {}
    best: dict[TaxiState, int] = {}

    def value_of(o: Outcome) -> float:
        return o.reward + (0.0 if o.done else values[o.state])

    for tick in range(model.shift_ticks - 1, -1, -1):
        for s in _all_states(model, tick):
            actions = range(4) if choose is None else (choose(s),)
            q = {a: sum(o.prob * value_of(o) for o in model.outcomes(s, a)) for a in actions}
            a_best = max(q, key=q.get)
            values[s], best[s] = q[a_best], a_best
    expected = sum(p * values[s] for p, s in model.initial_states())
    return expected, best


@lru_cache(maxsize=8)
def optimal_policy(model: TaxiModel = TaxiModel()) -> tuple[float, dict[TaxiState, int]]:
    """Expected fares per shift of the optimal (tick-aware) policy, and that policy."""
    return _backward(model, None)


def expected_return(model: TaxiModel, policy: Callable[[np.ndarray], int]) -> float:
    """Exact expected fares per shift of a policy that sees only the features."""
    return _backward(model, lambda s: policy(s.features()))[0]


class TaxiExact:
    """Taxi's exact model as the domain's capability (spec.toml's ``exact_model``):
    what ``Domain.exact`` returns, so policy code asks the domain instead of naming taxi."""

    def __init__(self, model: TaxiModel = TaxiModel()) -> None:
        self.model = model

    def expected_return(self, act: Callable[[np.ndarray], int]) -> float:
        return expected_return(self.model, act)

    def optimum(self) -> float:
        return optimal_policy(self.model)[0]

    def expected_returns(self, acts: list[Callable[[np.ndarray], int]]) -> list[float]:
        """``expected_return`` of many policies at once (``taxi_tables``: thousands a second)."""
        tables = self.tables()
        X = tables.features()
        return [float(v) for v in tables.returns(np.array([[act(x) for x in X] for act in acts]).reshape(len(acts), -1))]

    def expected_return_mixed(self, action_probs: Callable[[np.ndarray], np.ndarray]) -> float:
        """Exact expected return of a stochastic policy (a soft DDT that samples its action):
        ``action_probs`` maps a batch of feature vectors (n, 6) to probabilities (n, 4)."""
        tables = self.tables()
        return float(tables.mixed_returns(np.asarray(action_probs(tables.features()))[None])[0])

    def subtree_search(self, domain: str):
        """The polish's larger moves on this model's tables (subtree.py)."""
        from .subtree import SubtreeSearch

        return SubtreeSearch(domain)

    def tables(self):
        """The model as arrays over feature states (``taxi_tables``), for exhaustive searches."""
        from .tables import taxi_tables

        return taxi_tables(self.model)
