"""The two domains: specs, registered envs that pass Gymnasium's checker, and the taxi model."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from nl2policy.domains import DOMAINS, get_domain, make_env
from nl2policy.domains.highway.env import LANE_WIDTH, HighwayFeatures, kinematics_to_features
from nl2policy.domains.taxi.env import TaxiEnv, TaxiModel, TaxiState, expected_return, optimal_policy
from nl2policy.language.corpus import load_corpus
from nl2policy.policy.rollout import evaluate, random_policy, tree_policy


def test_unknown_domain_is_a_clear_error():
    with pytest.raises(KeyError, match="unknown domain 'boat'"):
        get_domain("boat")


def test_a_described_domains_dictionary_is_the_corpus_vocabulary_word_for_word():
    """Taxi and highway carry their dictionary in their folder; writers were shown the corpus's
    vocabulary.json, and the two must not drift apart."""
    import json

    from nl2policy.data import corpus_dir
    from nl2policy.language.corpus import covered_domains

    vocabulary = json.loads((corpus_dir() / "vocabulary.json").read_text())
    assert covered_domains() == {"taxi", "highway"} and set(DOMAINS) >= covered_domains()
    for name in covered_domains():
        d = get_domain(name)
        assert list(d.vocab.questions.items()) == list(vocabulary[name]["questions"].items())
        assert list(d.vocab.actions.items()) == list(vocabulary[name]["actions"].items())


@pytest.mark.parametrize("domain", DOMAINS)
def test_spec_matches_vocabulary(domain):
    d = get_domain(domain)
    assert d.weights.shape == (len(d.questions), len(d.features))
    assert (np.abs(d.weights).sum(axis=1) > 0).all(), "every question tests some feature"
    env = make_env(domain)
    assert env.action_space.n == len(d.actions)
    assert env.observation_space.shape == (len(d.features),)


def test_taxi_env_passes_checker():
    check_env(gym.make("nl2policy/taxi-v0").unwrapped)


def test_highway_env_passes_checker():
    check_env(gym.make("nl2policy/highway-v0").unwrapped)
    assert isinstance(gym.make("nl2policy/highway-v0").unwrapped, HighwayFeatures)


def test_taxi_questions_test_the_right_features(taxi):
    state = TaxiState(place=2, passenger=True, heavy=False, long_wait=True, tick=0)
    assert taxi.answers(state.features()) == {
        "at_airport": False, "at_village": False, "at_city": True, "has_passenger": True,
        "heavy_traffic": False, "long_wait": True}


def test_taxi_impossible_answers(taxi):
    assert len(taxi.possible_answer_sets) == 3 * 2 ** 3  # one place at a time, 3 free binary questions
    base = dict(at_airport=True, at_village=False, at_city=False, has_passenger=False, heavy_traffic=False, long_wait=False)
    assert taxi.is_possible(base)
    assert not taxi.is_possible({**base, "at_city": True})
    assert not taxi.is_possible({**base, "at_airport": False})


def test_highway_features_from_kinematics(highway):
    # ego in the middle lane at 28 m/s; a car 12 m ahead in my lane, one 30 m behind in the left lane
    obs = np.array([
        [1, 100.0, 1 * LANE_WIDTH, 28.0, 0.0],
        [1, 12.0, 0.0, -3.0, 0.0],
        [1, -30.0, -LANE_WIDTH, 1.0, 0.0],
        [0, 0, 0, 0, 0],
        [0, 0, 0, 0, 0],
    ])
    x = kinematics_to_features(obs)
    np.testing.assert_allclose(x, [0.12, 1.0, 0.30, 1.0, 0.5, 0.7], atol=1e-6)
    assert highway.answers(x) == {
        "car_ahead_close": True, "car_behind_close": False, "left_lane_free": True, "right_lane_free": True,
        "in_left_lane": False, "in_right_lane": False, "going_fast": True}
    obs[0, 2] = 0.0  # leftmost lane: no lane to the left
    x = kinematics_to_features(obs)
    answers = highway.answers(x)
    assert answers["in_left_lane"] and not answers["left_lane_free"]
    assert highway.is_possible(answers)


def test_taxi_simulation_matches_the_exact_model():
    tree = load_corpus("taxi")[4].tree  # passenger -> airport, else jammed -> village, else city
    act = tree_policy("taxi", tree)
    exact = expected_return(TaxiModel(), act)
    ev = evaluate("taxi", act, episodes=400, seed=0)
    assert abs(ev.mean_return - exact) < 4 * ev.stderr
    assert 7.0 < exact < 8.4


def test_taxi_scale_random_best_optimum():
    model = TaxiModel()
    optimum, policy = optimal_policy(model)
    assert 8.0 < optimum < 9.0
    rand = evaluate("taxi", random_policy("taxi", 1), episodes=300, seed=1)
    assert 0.8 < rand.mean_return < 2.2
    exact_returns = [expected_return(model, tree_policy("taxi", s.tree)) for s in load_corpus("taxi")[:60]]
    assert max(exact_returns) <= optimum + 1e-9
    assert max(exact_returns) > rand.mean_return + 4


def test_optimum_is_a_real_policy_of_the_env():
    """Acting with the computed optimal policy in the env earns its computed value."""
    model = TaxiModel()
    optimum, policy = optimal_policy(model)
    env = TaxiEnv(model)
    returns = []
    for ep in range(300):
        env.reset(seed=10_000 + ep)
        done, total = False, 0.0
        while not done:
            _, r, done, _, _ = env.step(policy[env.state])
            total += r
        returns.append(total)
    stderr = np.std(returns, ddof=1) / np.sqrt(len(returns))
    assert abs(np.mean(returns) - optimum) < 4 * stderr


@pytest.mark.slow
def test_every_corpus_tree_runs_in_its_env():
    taxi_env = make_env("taxi")
    for spec in load_corpus("taxi"):
        evaluate("taxi", tree_policy("taxi", spec.tree), episodes=1, seed=0, env=taxi_env)
    highway_env = make_env("highway")
    highway = get_domain("highway")
    obs, _ = highway_env.reset(seed=0)
    for spec in load_corpus("highway"):  # a few steps each: a full episode of 200 trees is minutes
        for _ in range(3):
            action = highway.tree_action(spec.tree, obs)
            obs, _, terminated, truncated, _ = highway_env.step(action)
            if terminated or truncated:
                obs, _ = highway_env.reset()


def test_evaluation_is_reproducible():
    tree = load_corpus("highway")[0].tree
    a = evaluate("highway", tree_policy("highway", tree), episodes=2, seed=5)
    b = evaluate("highway", tree_policy("highway", tree), episodes=2, seed=5)
    assert a.returns == b.returns


@pytest.mark.slow
@pytest.mark.parametrize("domain", DOMAINS)
def test_the_envs_never_produce_an_answer_set_the_spec_calls_impossible(domain):
    # discretization prunes branches that only impossible answer sets reach (Domain.forced_answer),
    # which changes nothing only if the env never produces one
    d, env = get_domain(domain), make_env(domain)
    rng = np.random.default_rng(0)
    obs, _ = env.reset(seed=0)
    seen = set()
    for _ in range(300):
        answers = d.answers(obs)
        assert d.is_possible(answers), answers
        seen.add(tuple(answers.values()))
        obs, _, terminated, truncated, _ = env.step(int(rng.integers(len(d.actions))))
        if terminated or truncated:
            obs, _ = env.reset(seed=int(rng.integers(1 << 30)))
    assert len(seen) >= 5  # the walk visited several kinds of state, not one


@pytest.mark.parametrize("domain", DOMAINS)
def test_a_domain_names_itself_gives_an_example_and_finds_its_briefing(domain, tmp_path):
    """What the app and `nl2policy run` show about a domain comes from the domain's own spec:
    no page or command keeps a list of domains."""
    from fastapi.testclient import TestClient

    from nl2policy.app.server import create_app
    from nl2policy.language.translate import translate

    d = get_domain(domain)
    assert d.title and d.example and d.example_tree is not None
    assert translate(domain, d.example).tree is not None
    with TestClient(create_app(tmp_path / "a.sqlite", tmp_path, results_dir=tmp_path), base_url="http://127.0.0.1") as client:
        assert client.get("/api/domains").json()[domain]["title"] == d.title
        briefing = client.get(f"/api/briefing/{domain}").json()["briefing"]
        assert len(briefing) > 200
        # the corpus briefing's own section, or (a domain nobody has described) its dictionary
        assert (d.briefing_section is not None) or all(q in briefing for q in d.vocab.questions.values())


@pytest.mark.parametrize("domain", DOMAINS)
def test_the_shipped_translator_reads_the_domains_example_as_its_tree(domain):
    """The example `nl2policy run` and the README show is translated as the spec says it means."""
    from nl2policy.language.translate import translate

    d = get_domain(domain)
    assert translate(domain, d.example).tree == d.example_tree


def test_a_misread_example_reaches_its_tree_by_answering_the_translators_questions():
    """Lunar's example in its first wording is read with two branches swapped (spec.toml); a
    user who answers the translator's questions as the tree would gets that tree in 3 answers."""
    from nl2policy.language.translate import translate

    d = get_domain("lunar")
    text = ("If the lander is tilted to the left, fire the right engine, and if it is tilted to the right, fire the "
            "left engine. Otherwise fire the main engine when it is falling fast, and fire no engine when it is not.")
    answers: list = []
    reading = translate("lunar", text)  # v3 and v7 read it with two branches swapped; any misreading is asked about
    while reading.questions and len(answers) < 3:
        situation = dict(reading.questions[0].situation)
        answers.append({"situation": situation, "do": d.example_tree.act(situation)})
        reading = translate("lunar", text, answers=answers)
        assert all(reading.tree.act(a["situation"]) == a["do"] for a in answers)
    assert reading.tree == d.example_tree


def test_an_example_tree_outside_the_dictionary_is_a_clear_error(tmp_path):
    import shutil
    from nl2policy.domains.spec import load_domain

    folder = tmp_path / "copy"
    shutil.copytree(get_domain("taxi").folder, folder)
    spec = (folder / "spec.toml").read_text()
    (folder / "spec.toml").write_text(spec.replace('example_tree = { if = "has_passenger"', 'example_tree = { if = "has_rocket"'))
    with pytest.raises(ValueError, match="example_tree"):
        load_domain(folder, "copy")


def test_lunar_vector_env_shows_repeated_policies_the_same_scenes():
    """The reset option repeat gives block k of the vector env the scenes of block 0, seeded as
    rollout.evaluate seeds its episodes, so policies are compared on common random numbers."""
    import gymnasium as gym

    env = gym.make_vec(get_domain("lunar").train_env_id, num_envs=6, vectorization_mode="vector_entry_point")
    obs, _ = env.reset(seed=7, options={"repeat": 2})
    single, _ = gym.make("LunarLander-v3").reset(seed=8)
    np.testing.assert_array_equal(obs[:3], obs[3:])
    np.testing.assert_array_equal(obs[1], single)
    with pytest.raises(ValueError, match="repeat"):
        env.reset(seed=0, options={"repeat": 4})
    env.close()


def test_lunar_batched_evaluation_counts_first_episodes_as_single_episodes_do():
    """The reset option once leaves finished episodes unstepped (a screen lasts as long as its
    longest episode, not 1,000 steps each): the batched returns are exactly rollout.evaluate's,
    episode by episode, and a finished env stays finished with zero reward."""
    import gymnasium as gym

    from nl2policy.policy.rollout import evaluate, evaluate_batched_many

    rng = np.random.default_rng(0)
    falls, random_act = (lambda x: 0), (lambda x: int(rng.integers(4)))
    batched = evaluate_batched_many("lunar", [lambda x: np.zeros(len(x), dtype=int)] * 2, 3, 11)
    single = evaluate("lunar", falls, 3, 11)
    assert batched[0].returns == batched[1].returns == pytest.approx(single.returns, abs=1e-9)
    env = gym.make_vec(get_domain("lunar").train_env_id, num_envs=2, vectorization_mode="vector_entry_point")
    env.reset(seed=3, options={"once": True})
    ended = np.zeros(2, dtype=bool)
    for _ in range(1_000):
        _, reward, terminated, truncated, _ = env.step(np.array([random_act(None), 0]))
        assert np.all(reward[ended] == 0.0) and np.all((terminated | truncated)[ended])
        ended |= terminated | truncated
        if ended.all():
            break
    assert ended.all()
    env.close()
