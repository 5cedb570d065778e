"""Seed 002's neural detectors and the method comparison, on a small stationary complex."""

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import CompileCounter, cli_fails

from hrgjax.diagnosis import compare as cp
from hrgjax.diagnosis import complex as cx
from hrgjax.diagnosis import neural as nl
from hrgjax.ins.platform import PlatformINS

SIZES = (1.5e-7, 3e-7)


@eqx.filter_jit  # one program (eagerly, each operation under vmap compiled apart)
def _healthy(ins, sets, k_len):
    """Healthy complexes' measurements, one (runs, k_len + 1, 2) array per `(key, runs)` of
    `sets`: each set's runs from `jax.random.split(key, runs)`, all in one batch."""
    keys = jnp.concatenate([jax.random.split(k, runs) for k, runs in sets])
    sim = lambda k: cx.simulate_complex(ins, dt=1.0, n_steps=k_len + 2, key=k)[1]
    z_all = jax.vmap(lambda k: cx.measurements(sim(k), 1.0, "accel_y", ins))(keys)
    out, start = [], 0
    for key, runs in sets:
        z = z_all[start : start + runs]
        start += runs
        out.append(z + 1e-9 * jax.random.normal(jax.random.fold_in(key, 1), z.shape))
    return out


@pytest.fixture(scope="module")
def data():
    ins = PlatformINS()
    tmpl = nl.onset_templates(ins, "accel_y", 1.0)
    # 3 training runs and 2 held out, on their own keys
    z_tr, z_te = _healthy(ins, ((jax.random.key(1), 3), (jax.random.key(2), 2)), 400)
    # 1200 training windows: onsets carry either sign, so each (INS, sign) pattern has half
    # the examples 600 gave when they were positive only (the MLP's held-out accuracy with
    # 600 signed windows was a draw: 0.74 or 0.84 for keys 6 and 7, chance 0.52)
    tr = nl.classifier_set(*nl.training_windows(z_tr, tmpl, jax.random.key(3), 1200, sizes=SIZES))
    te = nl.classifier_set(*nl.training_windows(z_te, tmpl, jax.random.key(4), 600, sizes=SIZES))
    return tmpl, z_tr, z_te, tr, te


def test_onset_templates_follow_eq7_and_the_pair_signs(data):
    """A unit north-accelerometer fault makes R/g·δφ'' step by the fault (half of it in the
    step it starts, the zero-order hold); INS 1 shows in both pairs, INS 2/3 in one with −."""
    tmpl = np.asarray(data[0])
    # (the Schuler loop bends the step by (ω_s t)²/2 ≈ 3e-6 within 2 s)
    np.testing.assert_allclose(tmpl[0, :3], [[0.5, 0.5], [1, 1], [1, 1]], atol=1e-5)
    np.testing.assert_allclose(tmpl[1, :3], [[-0.5, 0], [-1, 0], [-1, 0]], atol=1e-5)
    np.testing.assert_allclose(tmpl[2, :3], [[0, -0.5], [0, -1], [0, -1]], atol=1e-5)


def _chance(y):
    return np.bincount(np.asarray(y)).max() / len(y)


def test_every_neural_detector_beats_chance_on_held_out_windows(data):
    _, z_tr, z_te, (x, y), (xt, yt) = data
    chance = _chance(yt)
    dets = {
        "pnn_bank": nl.choose_sigma(nl.PNNBank, x, y, x[:200], y[:200], 4),
        "pnn_direct": nl.choose_sigma(nl.PNNDirect, x, y, x[:200], y[:200], 4),
        "som": nl.SOMDetector.fit(x, y, 4, key=jax.random.key(5), steps=5000),
        "mlp": nl.MLPClassifier.fit(x, y, 4, key=jax.random.key(6), steps=600),
    }
    # the SOM's held-out accuracy spreads over its key: 0.76-0.81 for keys 5-10 (chance 0.52),
    # and round-off moves a key within it (van_loan's scaling and squaring took key 5 from
    # above 0.767 to 0.762): its margin is below that spread, the others' 0.25
    margins = {"som": 0.2}
    for name, det in dets.items():
        acc = float(jnp.mean(det.classify(xt) == yt))
        assert acc > chance + margins.get(name, 0.25), (name, acc, chance)


def test_training_is_deterministic_for_a_key_and_differs_across_keys(data):
    _, _, _, (x, y), _ = data
    a = nl.SOMDetector.fit(x, y, 4, key=jax.random.key(5), steps=2000)
    b = nl.SOMDetector.fit(x, y, 4, key=jax.random.key(5), steps=2000)
    c = nl.SOMDetector.fit(x, y, 4, key=jax.random.key(9), steps=2000)
    np.testing.assert_array_equal(a.som.weights, b.som.weights)
    assert not np.allclose(a.som.weights, c.som.weights)
    m1 = nl.MLPClassifier.fit(x, y, 4, key=jax.random.key(6), steps=20)
    # a second fit of the same shapes compiles nothing (before: a closure over the data per
    # network, traced and compiled on every fit)
    with CompileCounter() as compiles:
        m2 = nl.MLPClassifier.fit(x, y, 4, key=jax.random.key(6), steps=20)
        m3 = nl.MLPClassifier.fit(x, y, 4, key=jax.random.key(7), steps=20)
    assert compiles.compiles == 0, compiles.names
    np.testing.assert_array_equal(m1.nets[0].layers[0].weight, m2.nets[0].layers[0].weight)
    assert not np.allclose(m1.nets[0].layers[0].weight, m3.nets[0].layers[0].weight)


def test_predictor_bank_names_the_onset_by_least_residual(data):
    """One predictor per INS and fault sign (7 hypotheses): held-out onsets of either sign
    within the last 3 samples are named by the least residual, mapped to their INS."""
    tmpl, z_tr, z_te, _, _ = data
    sets, classes = nl.predictor_sets(z_tr, tmpl, jax.random.key(7), 120, sizes=SIZES)
    assert classes == (0, 1, 1, 2, 2, 3, 3)
    # 10 hidden units, not the default 50: each Levenberg–Marquardt step factors a matrix
    # of the weights' size (392 here, 782 with 20 units: ≈ 8× the work)
    with CompileCounter() as compiles:
        pred = nl.MLPPredictor.fit(sets, key=jax.random.key(8), hidden=10, max_steps=8,
                                   classes=classes)  # fmt: skip
    # one Levenberg–Marquardt program for the seven hypotheses (same shapes)
    assert compiles.names.count("jit(least_squares)") == 1, compiles.names
    w, c, _ = nl.training_windows(z_te, tmpl, jax.random.key(10), 400, sizes=SIZES,
                                  onset_within_last=3)  # fmt: skip
    acc = float(jnp.mean(pred.classify_pairs(*nl.predictor_set(w)) == c))
    # held-out accuracy over 12 draws (data keys (1, 2), (11, 12), (21, 22), (31, 32), fit
    # keys 8–10): 0.925–0.9725 (with 20 hidden units 0.935–0.975), chance 0.48, no healthy
    # window named a fault. One predictor per INS trained on both signs (20 units) predicts
    # their mean (no jump) at an onset, where the window says nothing of the sign: 0.63–0.74
    # over the first 6 draws, 15–25 % of the healthy windows named a fault
    assert acc > 0.9, (acc, _chance(c))
    # classes as an array: two toy hypotheses of the shapes the NaN test below fits (one
    # Levenberg–Marquardt program for both; these windows' shapes compiled another)
    rng = np.random.default_rng(0)
    toy = [(rng.normal(size=(20, 6)), rng.normal(size=(20, 2))) for _ in range(2)]
    assert nl.MLPPredictor.fit(toy, key=jax.random.key(8), hidden=2, max_steps=1,
                               classes=jnp.array([0, 1])).classes == (0, 1)  # fmt: skip
    for bad in (classes, (0, -1), (0, 1.7), (1, 0), (False, True)):  # -1: "undecided"
        with pytest.raises(ValueError, match="one onset class per hypothesis"):
            nl.MLPPredictor.fit(sets[:2], key=jax.random.key(8), classes=bad)


def test_latch_holds_the_first_named_fault():
    c = jnp.array([[0, 0, 2, 0, 1, 0], [0, 0, 0, 0, 0, 0]])
    np.testing.assert_array_equal(nl.latch(c), [[0, 0, 2, 2, 2, 2], [0] * 6])
    # confirmation: a class must repeat on consecutive steps before it latches
    c2 = jnp.array([0, 3, 0, 1, 1, 0, 2, 2, 2])
    np.testing.assert_array_equal(nl.latch(c2, 2), [0, 0, 0, 0, 1, 1, 1, 1, 1])
    np.testing.assert_array_equal(nl.latch(c2, 3), [0] * 8 + [2])


def test_compare_scores_every_method_on_one_short_scenario():
    """End to end on a short stationary scenario: the table's keys, and the filter bank and
    the MLP classifier name the faulty INS (the bank every fault within 1 s of the onset, the
    briefly trained classifier at least two of three within seconds: its latch takes two more
    steps of confirmation) with no false alarm."""
    sc = cp.Scenario("short", t_fault=300.0, duration=400.0)
    res = cp.compare(sc, key=jax.random.key(3), n_faulty=3, n_healthy=1, n_train=2,
                     methods=("filter_bank", "mlp_classifier"), n_windows=600,
                     traces=True)  # fmt: skip
    rows = {r["name"]: r for r in res["methods"]}
    for r in rows.values():
        assert {"name", "detection_time_s", "false_alarm_rate", "wrong_diagnosis_rate",
                "step_cost_s"} <= set(r)  # fmt: skip
        # The classifier trains on two short runs here and is a draw: over keys 0–5 (CPU, 600
        # and 1 500 windows, 2 or 4 training runs) it missed one of the three faults in 1–2
        # of 6 draws and named the others within 3–6 s on average, 14 s at the latest; on a
        # GPU's round-off this key's draw missed one. The full benchmark (4 000 windows, 8
        # runs) detects 100 % (benchmarks/README.md). The filter bank has no such draw.
        if r["name"] == "filter_bank":
            assert r["detected"] == 1.0 and r["detection_time_max_s"] <= 1.0, r
        else:
            assert r["detected"] >= 2 / 3 and r["detection_time_s"] <= 8.0, r
            assert r["detection_time_max_s"] <= 15.0, r
        assert r["false_alarm_rate"] == 0.0 and r["wrong_diagnosis_rate"] < 0.05, r
    assert res["traces"]["filter_bank"].shape == res["traces"]["t_s"].shape
    assert "| filter_bank |" in cp.table(res)
    # the same scenario and shapes again: nothing traced or compiled (before: the banks' and
    # detectors' runs were fresh `jax.jit(lambda …)`s, the gain schedules and the classifier's
    # training eager scans: 7 compiles), and the same key gives the same scores
    with CompileCounter() as compiles:
        again = cp.compare(sc, key=jax.random.key(3), n_faulty=3, n_healthy=1, n_train=2,
                           methods=("filter_bank", "mlp_classifier"), n_windows=600)  # fmt: skip
    assert compiles.compiles == 0, compiles.names
    timing = ("step_cost_s", "train_s")
    for r, s in zip(res["methods"], again["methods"], strict=True):
        assert {k: v for k, v in r.items() if k not in timing} == {
            k: v for k, v in s.items() if k not in timing
        }
    # a later onset (another scenario of the same shape) is a value: nothing compiled (the
    # scenario was a static argument: 4 programs again, ≈ 9 s), the bank as prompt
    with CompileCounter() as compiles:
        later = cp.compare(dataclasses.replace(sc, name="later", t_fault=320.0),
                           key=jax.random.key(3), n_faulty=3, n_healthy=1, n_train=2,
                           methods=("filter_bank",), n_windows=600)  # fmt: skip
    assert compiles.compiles == 0, compiles.names
    bank = later["methods"][0]
    assert bank["detected"] == 1.0 and bank["detection_time_max_s"] <= 1.0, bank
    with pytest.raises(ValueError, match="unknown methods"):
        cp.compare(sc, methods=("nope",))
    with pytest.raises(ValueError, match="unknown scenario"):
        cp.compare("moon")
    with pytest.raises(ValueError, match="t_fault"):
        cp.compare(cp.Scenario("late", t_fault=500.0, duration=400.0))


@pytest.mark.slow(
    "~30 s: the 4000-s scenario through the CLI; fast tier: the same keys, table and "
    "filter-bank detection from compare() "
    "(test_compare_scores_every_method_on_one_short_scenario)"
)
def test_diagnose_cli_writes_the_design_keys(tmp_path, capsys):
    import json

    from hrgjax.cli import main

    out = tmp_path / "diag.json"
    args = ["diagnose", "--scenario", "stationary", "--methods", "filter_bank", "--runs", "1",
            "--json", str(out)]  # fmt: skip
    assert main(args) == 0
    rows = json.loads(out.read_text())["methods"]
    assert [r["name"] for r in rows] == ["filter_bank"]
    assert {"detection_time_s", "false_alarm_rate", "wrong_diagnosis_rate", "step_cost_s"} <= set(
        rows[0]
    )
    assert rows[0]["detection_time_s"] == 1.0 and rows[0]["false_alarm_rate"] == 0.0
    assert "| filter_bank |" in capsys.readouterr().out
    cli_fails(["diagnose", "--methods", "filter_bank,bogus", "--runs", "1"], capsys,
              "unknown methods")  # fmt: skip


def test_detectors_trained_the_default_way_name_the_ins_of_a_negative_fault(data):
    """Training onsets carry either sign: a PNN trained on the default windows names the
    faulty INS of held-out onsets of −(1.5–3e-7) as well as of +(1.5–3e-7). Trained on
    positive sizes only, it named another INS (INS 1's negative signature is INS 2's and
    3's positive one in the pairs (1,2), (1,3))."""
    tmpl, _, z_te, (x, y), _ = data
    det = nl.choose_sigma(nl.PNNDirect, x, y, x[:200], y[:200], 4)
    for sign in (1.0, -1.0):
        w, c, _ = nl.training_windows(z_te, sign * tmpl, jax.random.key(11), 300, sizes=SIZES,
                                      p_fault=1.0, signed=False)  # fmt: skip
        xt, yt = nl.classifier_set(w, c, None)
        acc = float(jnp.mean(det.classify(xt) == yt))
        assert acc > 0.8, (sign, acc)


def test_detectors_refuse_a_nan_window_on_the_host_and_pass_a_traced_one():
    """A NaN feature row was named a confident class (the PNNs' arg-max over NaN scores gave
    class 0, the SOM unit 0's label, the predictor bank's arg-min S0): each public classify
    refuses it in one line naming the input; under the caller's `jit`/`vmap` (compare's
    batched runs) the input passes unchecked, as before."""
    rng = np.random.default_rng(0)
    x, y = rng.normal(size=(40, 6)), np.arange(40) % 4
    q = x[:3].copy()
    q[1, 2] = np.nan
    dets = {
        "PNNDirect": nl.PNNDirect.fit(x, y, 4, 1.0),
        "PNNBank": nl.PNNBank.fit(x, y, 4, 1.0),
        "SOMDetector": nl.SOMDetector.fit(x, y, 4, key=jax.random.key(0), shape=(3, 3), steps=50),
        "MLPClassifier": nl.MLPClassifier.fit(x, y, 4, key=jax.random.key(0), hidden=(3,), steps=2),
    }
    jit_classify = jax.jit(lambda det, q: det.classify(q))
    for name, det in dets.items():
        with pytest.raises(ValueError, match=rf"^x \({name} query features\) must be finite; "
                                             r"it has nan at index \(1, 2\)$"):  # fmt: skip
            det.classify(q)
        assert jit_classify(det, q).shape == (3,)
        assert jax.vmap(det.classify)(q[None]).shape == (1, 3)
        np.testing.assert_array_equal(det.classify(x[:3]), jit_classify(det, x[:3]))
    # the threshold is a value: another one compiles nothing (each compiled `classify` again)
    # and classifies as the scores say
    for name in ("PNNDirect", "PNNBank", "MLPClassifier"):
        det = eqx.tree_at(lambda d: d.threshold, dets[name], jnp.asarray(0.999, float))
        with CompileCounter() as compiles:
            strict = np.asarray(det.classify(x[:3]))
        assert compiles.compiles == 0, (name, compiles.names)
        assert np.all((strict == 0) | (strict == np.asarray(dets[name].classify(x[:3])))), name
    with pytest.raises(ValueError, match=r"^threshold must be a number in \[0, 1\); got 1.5"):
        nl.PNNBank.fit(x, y, 4, 1.0, threshold=1.5)
    with pytest.raises(ValueError, match=r"^x \(MLPClassifier query features\) must be finite"):
        dets["MLPClassifier"].outputs(q)
    sets = [(x[:20], rng.normal(size=(20, 2))), (x[20:], rng.normal(size=(20, 2)))]
    pred = nl.MLPPredictor.fit(sets, key=jax.random.key(1), hidden=2, max_steps=1)
    yq = np.zeros((3, 2))
    with pytest.raises(ValueError, match=r"^x \(MLPPredictor query features\) must be finite"):
        pred.classify_pairs(q, yq)
    with pytest.raises(ValueError, match=r"^y \(MLPPredictor measured next steps\) must be"):
        pred.classify_pairs(x[:3], np.where(np.eye(3, 2) > 0, np.nan, 0.0))
    assert jax.jit(lambda p, a, b: p.classify_pairs(a, b))(pred, q, yq).shape == (3,)


def test_detectors_fit_with_a_traced_threshold_and_name_a_short_record():
    """Audit: `fit(threshold=<traced>)` (a sweep over thresholds under `vmap`: an ROC curve)
    said "threshold must be a number in [0, 1); got jax.Array of shape ()" — the detectors'
    fields took traced thresholds, their `fit` did not. A vmap over thresholds now equals one
    fit per threshold (a concrete 1.5 is still refused). `stream_classes` on a record shorter
    than a window said "taps must be in [1, 10]; got 20": it now names the record."""
    rng = np.random.default_rng(0)
    x, y = rng.normal(size=(40, 6)), np.arange(40) % 4
    ths = jnp.array([0.3, 0.6, 0.95])
    for cls in (nl.PNNDirect, nl.PNNBank):
        swept = jax.vmap(lambda th, cls=cls: cls.fit(x, y, 4, 1.0, threshold=th).classify(x))(ths)
        for th, got in zip(ths, swept, strict=True):
            np.testing.assert_array_equal(
                got, cls.fit(x, y, 4, 1.0, threshold=float(th)).classify(x)
            )
        assert len({tuple(np.asarray(c)) for c in swept}) > 1  # the threshold matters here
        with pytest.raises(ValueError, match=r"^threshold must be a number in \[0, 1\); got 1.5"):
            cls.fit(x, y, 4, 1.0, threshold=1.5)
    det = nl.PNNBank.fit(rng.normal(size=(8, 36)), np.arange(8) % 4, 4, 1.0)
    with pytest.raises(ValueError, match=r"^z must have at least 20 steps \(one full window of "
                                         r"taps = 20\); got a record of 10$"):  # fmt: skip
        nl.stream_classes(det, np.zeros((10, 2)))
