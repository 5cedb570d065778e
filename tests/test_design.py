"""Bench plans (issue 22, scope 1): segments as a pytree, the bench-time model against its
formula and finite differences, plan files, simulating a plan as one switch-on."""

import json
import re

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import CompileCounter, cli_fails

import hrgjax as hg
from hrgjax.calibration import design as d
from hrgjax.cli import main

SEGMENTS = [
    {"kind": "static", "temperature_c": -20.0, "wave_angle_deg": 10.0, "duration_s": 20.0},
    {"kind": "rotation", "temperature_c": -20.0, "wave_angle_deg": -30.0, "rate_dps": 5.0,
     "duration_s": 10.0},
    {"kind": "ramp", "temperature_start_c": -20.0, "temperature_end_c": -19.0,
     "wave_angle_deg": 45.0, "duration_s": 20.0},
]  # fmt: skip


def _slew_settle(dt, bench):
    """Independent transcription of BenchModel's transition cost [s] (numpy, per ΔT)."""
    delta = 0.05
    slew = dt * np.tanh(dt / delta) / bench.slew_c_per_min * 60.0
    settle = bench.settle_s * (1.0 - np.exp(-((dt / bench.settle_scale_c) ** 2)))
    return slew + settle + bench.reposition_s


def test_seed_plan_costs_most_of_two_days_by_the_formula():
    """The seed's 11 × 19 static and rotation points in bench order: 20.9 h of measuring,
    one 60-°C cool-down from 20 °C then ten 10-°C steps (each ≈ 10 min slew + 30 min soak),
    418 re-positionings — 36.0 h, as the formula written out by hand."""
    plan, bench = d.seed_bench_plan(), d.BenchModel()
    assert plan.size == 418 and plan.kind.count("rotation") == 209
    steps = np.array([-60.0] + [10.0] * 10)
    by_hand = 418 * 180.0 + np.sum(_slew_settle(steps, bench)) + (418 - 11) * 60.0
    assert float(d.bench_time_h(plan)) * 3600 == pytest.approx(by_hand, rel=1e-12)
    hours = bench.breakdown_h(plan)
    assert hours["measuring"] == pytest.approx(20.9)
    assert hours["settle"] == pytest.approx(5.5)  # 11 changes × 30 min
    assert hours["slew"] == pytest.approx(160 / 60, rel=1e-14)  # 160 °C at 1 °C/min
    assert hours["total"] == pytest.approx(sum(v for k, v in hours.items() if k != "total"))
    quick = d.seed_bench_plan(quick=True)
    assert quick.size == 2 * 3 * 19 and float(jnp.max(quick.duration_s)) == 120.0
    # the same grid with 1-min dwells: 418 × 2 min less measuring, the transitions unchanged
    short = d.seed_bench_plan(duration_s=60.0)
    assert short.segments()[5] == {**plan.segments()[5], "duration_s": 60.0}
    assert bench.breakdown_h(short)["measuring"] == pytest.approx(20.9 / 3)
    saved = float(d.bench_time_h(plan) - d.bench_time_h(short))
    assert saved == pytest.approx(418 * 120.0 / 3600, rel=1e-12)
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(ValueError, match="duration_s must be a positive run length"):
            d.seed_bench_plan(duration_s=bad)


def test_bench_time_gradient_equals_finite_differences_and_the_analytic_slope():
    """d(bench time)/d(plan) by jax.grad = central differences (1e-7) and, for durations,
    exactly 1 s/s; for a temperature, f′(ΔT_i) − f′(ΔT_{i+1}) written out."""
    rng = np.random.default_rng(0)
    n = 6
    t = rng.uniform(-40, 60, n)
    cols = (t, t, rng.uniform(-90, 90, n), np.zeros(n), rng.uniform(60, 600, n))
    plan = d.BenchPlan(("static",) * n, *(jnp.asarray(x) for x in cols))
    bench = d.BenchModel(settle_scale_c=8.0)  # a scale that makes the soak term bend
    f = lambda p: bench.bench_time_s(p)
    g = jax.grad(f)(plan)
    np.testing.assert_allclose(g.duration_s, 1.0, rtol=0, atol=1e-15)

    def fd(i, h=1e-4):
        up = lambda s: plan.__class__(plan.kind, plan.temperature_c.at[i].add(s),
                                      plan.temperature_end_c.at[i].add(s), plan.wave_angle_deg,
                                      plan.rate_dps, plan.duration_s)  # fmt: skip
        return (float(f(up(h))) - float(f(up(-h)))) / (2 * h)

    # a static segment's start and end temperature are one number: the total derivative
    total = g.temperature_c + g.temperature_end_c
    for i in range(n):
        assert float(total[i]) == pytest.approx(fd(i), rel=1e-7, abs=1e-6)

    def fprime(dt):
        delta = 0.05
        return ((np.tanh(dt / delta) + dt / delta * (1 - np.tanh(dt / delta) ** 2))
                * 60.0 / bench.slew_c_per_min
                + bench.settle_s * 2 * dt / bench.settle_scale_c**2
                * np.exp(-((dt / bench.settle_scale_c) ** 2)))  # fmt: skip

    temps = np.asarray(plan.temperature_c)
    dts = np.diff(np.concatenate([[bench.start_temperature_c], temps]))
    analytic = fprime(dts) - np.concatenate([fprime(dts[1:]), [0.0]])
    np.testing.assert_allclose(total, analytic, rtol=1e-12, atol=1e-12)


def test_plan_file_round_trip_and_every_bad_input_named(tmp_path):
    plan = d.BenchPlan.from_segments(SEGMENTS)  # its ramp: 3 °C/min
    bench = d.BenchModel(slew_c_per_min=5.0, settle_s=900.0)
    path = d.save_plan(plan, tmp_path / "plan.json", bench)
    doc = json.loads((tmp_path / "plan.json").read_text())
    assert doc["segments"] == SEGMENTS  # the contract's keys, units in their names
    assert doc["bench_time_h"] == pytest.approx(float(d.bench_time_h(plan, bench)))
    back, bench_back = d.load_plan(path)
    assert back.kind == plan.kind and bench_back == bench
    for a, b in zip(jax.tree_util.tree_leaves(back), jax.tree_util.tree_leaves(plan), strict=True):
        np.testing.assert_array_equal(a, b)

    def bad(segments, match, **doc):
        f = tmp_path / "bad.json"
        f.write_text(json.dumps({"segments": segments, **doc}))
        with pytest.raises(ValueError, match=match):
            d.load_plan(f)

    s0 = SEGMENTS[0]
    bad([{**s0, "kind": "hold"}], r"segments\[0\]: 'kind' must be one of")
    bad(
        [{k: v for k, v in s0.items() if k != "duration_s"}],
        r"\[0\] \(static\): missing 'duration_s' \[s\]",
    )
    bad([{**s0, "temperature": 0.0}], r"unknown key 'temperature'; expected 'temperature_c' \[°C\]")
    bad([{**s0, "rate_dps": 1.0}], r"unknown key 'rate_dps'")  # a static segment does not turn
    bad(
        [s0, {**SEGMENTS[1], "rate_dps": 0.0}], r"segment 1 \(rotation\): rate_dps must be non-zero"
    )
    bad([{**s0, "duration_s": -1.0}], r"segment 0 \(static\): duration_s must be > 0")
    bad([{**s0, "wave_angle_deg": "ten"}], r"'wave_angle_deg' must be a finite number")
    bad([], r"segments is empty")
    bad([s0], r"unknown key\(s\) \['plan'\]", plan=1)
    bad([s0], r"'bench' must be an object with keys", bench={"slew": 1.0})
    bad([s0], r"slew_c_per_min must be > 0", bench={"slew_c_per_min": 0.0})
    fast = d.BenchPlan.from_segments([{**SEGMENTS[2], "temperature_end_c": 40.0}])
    with pytest.raises(ValueError, match=r"segment 0 \(ramp\): 180 °C/min is faster"):
        d.BenchModel().check(fast)
    with pytest.raises(ValueError, match=r"BenchPlan.temperature_c must have shape \(2,\)"):
        d.BenchPlan(("static", "static"), *(jnp.zeros(3),) * 4, jnp.ones(3))  # fmt: skip
    for bad in (0, 1, 8.0, True):
        with pytest.raises(ValueError, match=r"^nodes must be a whole number ≥ 2 .* got"):
            d.information(plan, nodes=bad)


# A plan as the search leaves it (issue 43): temperatures and angles to the last bit, wave
# angles anywhere, a ramp a little faster than the chamber once its ends are rounded.
RAW = [
    {"kind": "static", "temperature_c": -39.4150101746599, "wave_angle_deg": -167.2,
     "duration_s": 119.7},
    {"kind": "rotation", "temperature_c": -39.4150101746599, "wave_angle_deg": 270.04,
     "rate_dps": 4.996, "duration_s": 113.2},
    {"kind": "ramp", "temperature_start_c": -39.4150101746599,
     "temperature_end_c": 42.464998885560334, "wave_angle_deg": -89.97, "duration_s": 4912.9},
    {"kind": "static", "temperature_c": 42.464998885560334, "wave_angle_deg": 89.96,
     "duration_s": 600.4},
    {"kind": "rotation", "temperature_c": 42.464998885560334, "wave_angle_deg": -90.0,
     "rate_dps": -0.004, "duration_s": 72.0},
]  # fmt: skip


def _on_grid(x, step):
    k = np.asarray(x) / step
    return np.allclose(k, np.round(k), rtol=0, atol=1e-9)


def test_round_plan_puts_every_number_on_the_bench_grid_idempotently():
    """Temperatures to 0.1 °C, wave angles wrapped to (−90°, 90°] and to 0.1°, rates to
    0.01 °/s, durations to whole seconds (ramps up, never faster than the chamber); each
    float prints as written; a rounded plan rounds to itself; other steps and a budget."""
    plan, bench = d.BenchPlan.from_segments(RAW), d.BenchModel()
    out = d.round_plan(plan, bench)
    segs = out.segments()
    assert [s.get("temperature_c", s.get("temperature_start_c")) for s in segs] == [
        -39.4, -39.4, -39.4, 42.5, 42.5]  # fmt: skip
    assert segs[2]["temperature_end_c"] == 42.5  # a ramp still ends at its level
    # −167.2 ≡ 12.8; 270.04 ≡ 90.04 ≡ −89.96 → 90.0 (the edge, the same wave); −90 → +90
    assert [s["wave_angle_deg"] for s in segs] == [12.8, 90.0, 90.0, 90.0, 90.0]
    assert segs[1]["rate_dps"] == 5.0 and segs[4]["rate_dps"] == -0.01  # a rotation turns
    # static/rotation down; the ramp's 81.9 °C at 1 °C/min need 4914 s, more than 4913
    assert [s["duration_s"] for s in segs] == [119.0, 113.0, 4914.0, 600.0, 72.0]
    bench.check(out)
    for seg in segs:  # the shortest repr: −39.4, not −39.400000000000006
        for k, x in seg.items():
            if k != "kind":
                assert repr(x) == repr(round(x, 2)), (k, x)
    again = d.round_plan(out, bench)
    for a, b in zip(jax.tree_util.tree_leaves(again), jax.tree_util.tree_leaves(out),
                    strict=True):  # fmt: skip
        np.testing.assert_array_equal(a, b)
    # random plans, other steps (0.7° does not divide 180°: the nearest point inside)
    rng = np.random.default_rng(1)
    n = 200
    t = rng.uniform(-40, 60, n)
    angles = np.concatenate([rng.uniform(-400, 400, n - 8),
                             [-90.0, 90.0, -89.96, 89.96, 180.0, -180.0, 269.99, -270.05]])  # fmt: skip
    cols = (t, t, angles, np.zeros(n), rng.uniform(60, 600, n))
    plan = d.BenchPlan(("static",) * n, *(jnp.asarray(x) for x in cols))
    for steps in (dict(temperature_step=0.1, angle_step=0.1, time_step=1.0),
                  dict(temperature_step=0.25, angle_step=0.7, time_step=5.0),
                  dict(temperature_step=1.0, angle_step=0.05, time_step=0.5)):  # fmt: skip
        out = d.round_plan(plan, bench, **steps)
        a = np.asarray(out.wave_angle_deg)
        assert np.all((a > -90.0) & (a <= 90.0))
        gap = np.abs(np.mod(a - angles + 90.0, 180.0) - 90.0)  # the same wave, to a step
        edge = (180.0 - 2 * (90.0 // steps["angle_step"]) * steps["angle_step"]) / 2  # 0.4°
        assert gap.max() <= max(steps["angle_step"] / 2, edge) + 1e-9
        assert _on_grid(a, steps["angle_step"])
        assert _on_grid(out.temperature_c, steps["temperature_step"])
        assert np.abs(np.asarray(out.temperature_c) - t).max() <= steps["temperature_step"] / 2
        assert _on_grid(out.duration_s, steps["time_step"])
        again = d.round_plan(out, bench, **steps)
        for f in ("temperature_c", "wave_angle_deg", "duration_s"):
            np.testing.assert_array_equal(getattr(again, f), getattr(out, f))
    # a budget: the longest static segments give up whole steps until it holds
    plan = d.BenchPlan.from_segments(RAW)
    budget = float(d.bench_time_h(d.round_plan(plan, bench), bench)) - 0.01
    fit = d.round_plan(plan, bench, budget_h=budget)
    assert float(d.bench_time_h(fit, bench)) <= budget
    assert fit.segments()[3]["duration_s"] == 600.0 - 36.0  # 0.01 h off the longest
    with pytest.raises(ValueError, match=r"budget_h=1: the plan rounded .* cannot be short"):
        d.round_plan(plan, bench, budget_h=1.0)
    for name, unit in (("temperature_step", "°C"), ("angle_step", "° electrical"),
                       ("time_step", "s"), ("rate_step", "°/s")):  # fmt: skip
        for bad in (0.0, -0.1, float("nan")):
            with pytest.raises(
                ValueError, match=rf"^{name} must be a finite number > 0 \[{unit}\]"
            ):
                d.round_plan(plan, **{name: bad})


def test_criterion_and_information_are_periodic_in_180_degrees_of_wave_angle():
    """Every modelled effect the design sees is a harmonic of 2θ electrical (PHYSICS.md §1),
    which is what lets `round_plan` wrap the angles: the information (grey box and
    empirical surrogate) and a criterion of a plan — static, rotation, a ramp at rest and
    one that turns — equal the plan's with every wave angle ±180° to round-off. A term in θ
    alone would break it; 90° (the other harmonic's half-period) does change them. (Every
    criterion of a concrete plan is a function of its information; `d` compiles in < 1 s,
    the default's flights in ≈ 6 s: the design CLI test checks the default on its plan.)"""
    segs = [{**SEGMENTS[0], "duration_s": 600.0}, {**SEGMENTS[1], "duration_s": 120.0},
            {**SEGMENTS[2], "temperature_end_c": 40.0, "duration_s": 3600.0},
            {**SEGMENTS[2], "temperature_start_c": 40.0, "temperature_end_c": 20.0,
             "wave_angle_deg": 70.0, "rate_dps": 2.0, "duration_s": 2400.0}]  # fmt: skip
    plan = d.BenchPlan.from_segments(segs)
    shifted = lambda s: eqx.tree_at(lambda q: q.wave_angle_deg, plan, plan.wave_angle_deg + s)
    for model in ("physical", "empirical"):
        f0 = np.asarray(d.information(plan, model=model))
        for s in (180.0, -180.0):
            np.testing.assert_allclose(d.information(shifted(s), model=model), f0, rtol=0,
                                       atol=1e-13 * np.abs(f0).max())  # fmt: skip
    c0 = float(d.criterion(plan, "d"))
    for s in (180.0, -180.0):
        assert float(d.criterion(shifted(s), "d")) == pytest.approx(c0, rel=1e-11)
    assert abs(float(d.criterion(shifted(90.0), "d")) - c0) > 1e-3
    quarter = np.asarray(d.information(shifted(90.0)))
    assert np.abs(quarter - np.asarray(d.information(plan))).max() > 1e-3 * np.abs(quarter).max()


def test_plan_file_keeps_the_rounded_values_and_both_criteria_and_old_files_load(tmp_path):
    """save_plan with the criterion and resolution blocks writes the rounded numbers as
    they print (−39.4) and load_plan gives them back exactly; a file without the new
    blocks (the contract's) loads as before; bad blocks are named."""
    bench = d.BenchModel()
    plan = d.round_plan(d.BenchPlan.from_segments(RAW), bench)
    criterion = {"kind": "drift+warmup", "model": "physical", "unit": "°",
                 "optimised": 0.0194, "rounded": 0.01943}  # fmt: skip
    resolution = {"temperature_c": 0.1, "wave_angle_deg": 0.1, "duration_s": 1.0,
                  "rate_dps": 0.01}  # fmt: skip
    path = d.save_plan(plan, tmp_path / "plan.json", bench, criterion=criterion,
                       resolution=resolution)  # fmt: skip
    text = (tmp_path / "plan.json").read_text(encoding="utf-8")
    assert '"temperature_c": -39.4,' in text and '"unit": "°"' in text
    assert "00000" not in text.split('"bench_time_h"')[0]  # segments print as written
    doc = json.loads(text)
    assert doc["segments"] == plan.segments() and doc["criterion"] == criterion
    assert doc["resolution"] == resolution
    assert doc["bench_time_h"] == float(d.bench_time_h(plan, bench))  # of the rounded plan
    back, _ = d.load_plan(path)
    for a, b in zip(jax.tree_util.tree_leaves(back), jax.tree_util.tree_leaves(plan), strict=True):
        np.testing.assert_array_equal(a, b)
    # load → save keeps the blocks: the same file again, byte for byte
    back, bench_back, blocks = d.load_plan(path, blocks=True)
    assert blocks == {"criterion": criterion, "resolution": resolution}
    again = d.save_plan(back, tmp_path / "again.json", bench_back, **blocks)
    assert (tmp_path / "again.json").read_bytes() == (tmp_path / "plan.json").read_bytes()
    assert d.load_plan(again, blocks=True)[2] == blocks
    old = tmp_path / "old.json"  # the contract's keys alone, as before issue 43
    old.write_text(json.dumps({"segments": RAW, "bench_time_h": 3.15}))
    back, bench_back = d.load_plan(old)
    assert back.segments() == RAW and bench_back == d.BenchModel()
    assert d.load_plan(old, blocks=True)[2] == {}
    for block, match in (
        ({"criterion": {**criterion, "rounded": "small"}}, r"'criterion': 'rounded' must be"),
        ({"criterion": {"kind": "drift"}}, r"'criterion' must be an object with keys"),
        ({"resolution": {"temperature_c": 0.0}}, r"'temperature_c' must be a step > 0 \[°C\]"),
        ({"resolution": {"angle": 0.1}}, r"'resolution' must be an object with keys from"),
    ):
        bad = tmp_path / "bad.json"
        bad.write_text(json.dumps({"segments": RAW, **block}))
        with pytest.raises(ValueError, match=match):
            d.load_plan(bad)


@pytest.fixture(scope="module")
def quiet():
    return hg.presets.tvg3_like(noise=False)


def test_each_segment_is_the_simulation_of_its_profile(quiet):
    """Segment i is run i; each equals hg.simulate of its two-knot profile (static,
    5 °/s rotation, 1-°C ramp) to 1e-10 rad; the columns carry the plan's values."""
    plan = d.BenchPlan.from_segments(SEGMENTS)
    k = jax.random.key(0)  # the keys `hrgjax simulate --plan-file` passes: its program
    data = d.simulate_plan(quiet, plan, key=k, bias_key=jax.random.fold_in(k, 1))
    assert np.unique(data.run).tolist() == [0, 1, 2]
    for i, s in enumerate(SEGMENTS):
        rows = data.run == i
        t0 = s.get("temperature_c", s.get("temperature_start_c"))
        t1 = s.get("temperature_end_c", t0)
        prof = hg.Profile.piecewise([0.0, s["duration_s"]], [s.get("rate_dps", 0.0)] * 2,
                                    [t0, t1], wave_angle0_deg=s["wave_angle_deg"])  # fmt: skip
        dt = d.DT_OUT[s["kind"]]
        rec = hg.simulate(quiet, prof, ts=jnp.arange(0.0, s["duration_s"] + dt / 2, dt))
        np.testing.assert_allclose(data["wave_angle_deg"][rows], np.rad2deg(rec.wave_angle),
                                   rtol=0, atol=np.rad2deg(1e-10))  # fmt: skip
        temp = data["temperature_c"][rows]
        assert temp[0] == t0 and temp[-1] == pytest.approx(t1)
        assert np.all(data["table_rate_dps"][rows] == s.get("rate_dps", 0.0))


@pytest.mark.slow(
    "~50 s: eight simulator and residual programs for three run lengths; fast tier: the "
    "physical fit on one layout (test_calibration, test_loops_plant), the segments' "
    "simulation (test_each_segment_is_the_simulation_of_its_profile)"
)
def test_physical_fit_pads_rare_run_lengths_without_changing_a_window(quiet, monkeypatch):
    """Runs of rare lengths share a compiled group padded to a power of two of samples, and
    neighbouring lengths one group where that is cheaper than compiling another: every
    window rate the fit simulates (static, 10-s rotation windows, 300-s ramp windows, the
    ramp's last partial one) equals the unpadded layout's to 1e-6 °/h (the adaptive solver
    steps differently towards a later end: 3e-8 °/h seen), and the padded tail adds no
    residual."""
    from hrgjax.calibration import _physical_fit, _physical_groups, physical

    segs = [{**SEGMENTS[0], "duration_s": 70.0}, {**SEGMENTS[1], "duration_s": 40.0},
            {**SEGMENTS[2], "temperature_end_c": -18.0, "duration_s": 400.0}]  # fmt: skip
    data = d.simulate_plan(quiet, d.BenchPlan.from_segments(segs))
    values = d.nominal_values()
    residuals = eqx.filter_jit(_physical_fit.window_residuals)
    out, lengths = {}, {}
    merged = _physical_groups.merge_buckets
    apart = lambda buckets, short: [(k[0], v) for k, v in buckets.items()]  # noqa: E731
    # every length its own group / every run padded and lengths merged (as the default does)
    for shared, merge in ((1, apart), (100, merged)):
        monkeypatch.setattr(_physical_groups, "SHARED_LENGTH_RUNS", shared)
        monkeypatch.setattr(_physical_groups, "merge_buckets", merge)
        groups = _physical_groups.fit_groups(data, 10.0, physical.K_E_NOMINAL)
        weights = _physical_groups.window_weights(groups)
        res = residuals(groups, values, physical.K_E_NOMINAL)
        key = (shared, merge is merged)
        out[key] = [np.asarray(res[k])[weights[k] > 0] / weights[k][weights[k] > 0]
                    for k in (True, False)]  # fmt: skip
        lengths[key] = sorted(g.t.shape[1] for g in groups)
        assert np.all(np.asarray(res[True])[weights[True] == 0] == 0.0)
    # 71 samples → 128, 81 (0.5 s) → 128, 401 → 512, and the 1-s ones merged: 71 → 512
    assert lengths[(1, False)] == [71, 81, 401] and lengths[(100, True)] == [128, 512]
    # at rest: the static, the ramp's 300-s window and its partial 100-s one; moving: 4
    assert [r.size for r in out[(1, False)]] == [3, 4]
    for a, b in zip(out[(1, False)], out[(100, True)], strict=True):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-6 * hg.units.DEG_PER_H)


def test_partition_is_the_cheapest_split_by_brute_force():
    """The dynamic programme behind the merged groups returns, for random costs (some
    forbidden), a split into contiguous runs that costs what the cheapest of all 2^(n−1)
    splits costs."""
    import itertools
    import math

    from hrgjax.calibration._grouping import partition

    rng = np.random.default_rng(1)
    for n in (1, 2, 5, 7):
        table = rng.uniform(1, 10, (n + 1, n + 1))
        forbidden = rng.uniform(size=(n + 1, n + 1)) < 0.2

        def cost(i, j, table=table, forbidden=forbidden):
            return math.inf if j - i > 1 and forbidden[i, j] else table[i, j]

        parts = partition(n, cost)
        assert [a for a, _ in parts] == [0] + [b for _, b in parts[:-1]] and parts[-1][1] == n
        brute = min(
            sum(cost(a, b) for a, b in itertools.pairwise((0, *cuts, n)))
            for k in range(n)
            for cuts in itertools.combinations(range(1, n), k)
        )
        assert sum(cost(a, b) for a, b in parts) == pytest.approx(brute, rel=1e-12)


def test_simulation_groups_merge_lengths_where_a_compile_costs_more(monkeypatch):
    """simulate_plan's groups partition the segments; each runs at least as long as its
    longest member; the seed plan keeps its two exact lengths; rare nearby rotation lengths
    share one simulator; the full model's (whose steps are dear) are not merged; a dear
    compile merges every length of one output interval up to the guard on estimated steps."""
    from hrgjax.calibration import _plan_simulation

    segs = [
        {
            "kind": "rotation",
            "temperature_c": 20.0,
            "wave_angle_deg": 0.0,
            "rate_dps": 5.0,
            "duration_s": dur,
        }
        for dur in [121.0] * 4 + [122.0] * 4 + [128.0] * 2
    ]
    segs += [{"kind": "static", "temperature_c": 20.0, "wave_angle_deg": 0.0,
              "duration_s": dur} for dur in (700.0, 1500.0, 3000.0)]  # fmt: skip
    plan = d.BenchPlan.from_segments(segs)

    def groups(plan, model="averaged"):
        dts = dict(d.DT_OUT)
        n_out = [round(float(t) / dts[k]) for t, k in zip(plan.duration_s, plan.kind, strict=True)]
        out = _plan_simulation.simulation_groups(plan, n_out, dts, model)
        members = sorted(m for v in out.values() for m in v)
        assert members == list(range(plan.size))  # each segment exactly once
        for (samples, dt), v in out.items():
            assert all(samples >= n_out[m] + 1 and dts[plan.kind[m]] == dt for m in v)
        return {k: len(v) for k, v in out.items()}

    assert groups(d.seed_bench_plan()) == {(361, 0.5): 209, (181, 1.0): 209}
    merged = groups(plan)
    assert merged[(512, 0.5)] == 10 and len(merged) < 6
    units = {(243, 0.5): 4, (245, 0.5): 4, (512, 0.5): 2, (1024, 1.0): 1, (2048, 1.0): 1,
             (4096, 1.0): 1}  # fmt: skip
    assert groups(plan, "full") == units
    monkeypatch.setattr(
        _plan_simulation, "SIMULATOR_COMPILE_S", 1e6
    )  # compiling dear: one group per dt
    assert groups(plan) == {(512, 0.5): 10, (4096, 1.0): 3}
    monkeypatch.setattr(_plan_simulation, "MERGED_STEPS_MAX", 2000)  # but never past the step guard
    assert groups(plan) == {(512, 0.5): 10, (1024, 1.0): 1, (2048, 1.0): 1, (4096, 1.0): 1}


def test_simulate_plan_file_cli(tmp_path, quiet, capsys):
    plan = d.BenchPlan.from_segments(SEGMENTS)  # its ramp: 3 °C/min
    path = d.save_plan(plan, tmp_path / "plan.json", d.BenchModel(slew_c_per_min=5.0))
    out = tmp_path / "data.csv"
    args = ["simulate", "--plan-file", str(path), "--no-noise", "--out", str(out)]
    assert main(args) == 0
    data = hg.load(out)
    assert np.unique(data.run).tolist() == [0, 1, 2]
    assert "3 segments, bench time" in capsys.readouterr().out
    slow = tmp_path / "slow.json"  # a 1-°C/min chamber cannot ramp it (save_plan refuses)
    slow.write_text(json.dumps(d.plan_to_json(plan, d.BenchModel(slew_c_per_min=5.0))
                               | {"bench": d.BenchModel().to_json()}))  # fmt: skip
    cli_fails(["simulate", "--plan-file", str(slow), "--out", str(out), "--force"], capsys,
              r"slow.json: segment 2 \(ramp\): 3 °C/min is faster than")  # fmt: skip
    cli_fails(["simulate", "--plan-file", str(path), "--plan", "seed", "--out", str(out), "--force"],
              capsys, "either --plan or --plan-file")  # fmt: skip
    cli_fails(["simulate", "--plan-file", str(tmp_path / "none.json"), "--out", str(out), "--force"],
              capsys, r"--plan-file: .*none.json: no such file")  # fmt: skip


# --- the design criteria (scope 2) ---------------------------------------------------------

IDEAL_READOUT = d.nominal_values().at[9:].set(0.0)  # gain mismatch and cross-talk off


def test_measured_rate_is_the_ideal_loop_law_and_its_jacobian_is_finite_differences():
    """With a perfect readout the measured rate is −k_e(Ω + b(T)) + ½Δ(1/τ)(T) sin 2(θ−θ_τ(T))
    written out (PHYSICS.md §10), with no Ṫ term; with the preset's readout, jacfwd equals
    central differences for all twelve parameters, and a bias reads through k_e(T)·dθ̂/dθ
    (`Readout.angle_slope` of the preset, 3.5 % peak to peak over θ at −25 °C), as
    `simulate` reads a switch-on bias: a Monte Carlo's truth adds the session's bias so
    (`benchmarks/design_mc.py`; added as a constant it read a 4×-long plan's drift 1.50×
    its prediction for 1.21×, docs/design.md)."""
    v = np.asarray(IDEAL_READOUT)
    theta, temp, omega = 0.7, -25.0, 5.0 * hg.units.DEG_PER_S
    dt = temp - 20.0
    bias = v[2] + v[3] * dt + v[4] * dt**2
    law = 0.5 * v[5] * np.exp(v[6] * dt) * np.sin(2 * (theta - v[7] - v[8] * dt))
    by_hand = -v[0] * (1 + v[1] * dt) * (omega + bias) + law
    got = d.measured_rate(jnp.asarray(v), jnp.asarray(theta), jnp.asarray(temp), omega, 0.05)
    assert float(got) == pytest.approx(by_hand, rel=1e-13)
    values = d.nominal_values().at[11].set(2e-3)  # cross-talk on as well
    f = jax.jit(lambda x: d.measured_rate(x, jnp.asarray(theta), jnp.asarray(temp), omega, 0.05))
    jac = np.asarray(jax.jacfwd(f)(values))
    for i in range(12):
        h = 1e-6 * max(abs(float(values[i])), 1e-3)
        fd = (float(f(values.at[i].add(h))) - float(f(values.at[i].add(-h)))) / (2 * h)
        assert jac[i] == pytest.approx(fd, rel=1e-6, abs=1e-9 * abs(jac).max()), i
    angles = jnp.linspace(-1.5, 1.5, 7)
    rate = lambda x, th: d.measured_rate(x, th, jnp.asarray(temp), 0.0, 0.0)  # noqa: E731
    per_bias = jax.vmap(jax.grad(rate), (None, 0))(d.nominal_values(), angles)[:, 2]
    gyro = hg.presets.tvg3_like().at(temp)
    want = -gyro.resonator.k_e * gyro.readout.angle_slope(angles)
    np.testing.assert_allclose(per_bias, want, rtol=1e-12)
    assert np.ptp(np.asarray(want)) > 0.03 * gyro.resonator.k_e  # not a constant k_e


def ols_slope_variance(n, dt, arw, angle_white):
    """Exact variance of a least-squares slope over n samples spaced dt of a random walk of
    density `arw` plus white noise `angle_white` per sample: wᵀ C w (numpy)."""
    t = np.arange(n) * dt
    w = (t - t.mean()) / np.sum((t - t.mean()) ** 2)
    # wᵀ min(tᵢ, tⱼ) w = Δt Σₖ (Σ_{i≥k} wᵢ)², k ≥ 1 (a random walk is a sum of increments)
    tail = np.cumsum(w[::-1])[::-1][1:]
    return float(arw**2 * dt * np.sum(tail**2) + angle_white**2 * np.sum(w**2))


@pytest.mark.parametrize("samples, dt", [(20, 0.5), (61, 1.0), (301, 1.0)])
def test_window_density_is_the_least_squares_slope_variance(samples, dt):
    """`window_density`² / length = the exact variance of a window's least-squares slope
    under angle random walk + white angle noise (the default gyro's: 1″ per sample)."""
    arw, white = d.pattern_arw(), d.pattern_angle_white()
    length = samples * dt
    got = float(d.window_density(arw, white, samples, dt, length)) ** 2 / length
    assert got == pytest.approx(ols_slope_variance(samples, dt, arw, white), rel=1e-10)


def test_information_is_one_over_the_slope_variance_and_adds_over_a_split_segment():
    """A static segment (one window) informs the bias as k_e²/var(slope) and its slope as
    k_e² ΔT²/var(slope), var the exact least-squares slope variance of its samples; a
    rotation split in two halves (the second from where the first left the pattern) carries
    the information of the whole (no Gauss–Markov rate: `gauss_markov=(0, 1)`), and an
    hour's rotation that of its ten 6-min pieces, an hour's turning ramp that of its sixty
    1-min pieces; a plan's
    information is the sum of its segments' alone (statics take one quadrature node, the
    others 64, all in one vmapped Jacobian: no point is counted against another segment)."""
    from hrgjax.calibration._information import ramp_panels

    arw, white, no_gm = 1e-5, 2e-6, dict(gauss_markov=(0.0, 1.0))
    static = d.BenchPlan.from_segments([SEGMENTS[0]])
    info = np.asarray(d.information(static, IDEAL_READOUT, arw, angle_white=white, **no_gm))
    k_e, dur, dt = float(IDEAL_READOUT[0]), SEGMENTS[0]["duration_s"], -40.0
    var = ols_slope_variance(round(dur) + 1, 1.0, arw, white)
    assert info[2, 2] == pytest.approx(k_e**2 / var, rel=1e-10)
    assert info[3, 3] / info[2, 2] == pytest.approx(dt**2, rel=1e-12)
    rot = {**SEGMENTS[1], "duration_s": 60.0}
    half = {**rot, "duration_s": 30.0}
    swept = -k_e * rot["rate_dps"] * 30.0  # electrical degrees turned in the first half
    halves = d.BenchPlan.from_segments(
        [half, {**half, "wave_angle_deg": half["wave_angle_deg"] + swept}]
    )
    whole = d.BenchPlan.from_segments([rot])
    a = np.asarray(d.information(halves, IDEAL_READOUT, arw, angle_white=white, **no_gm))
    b = np.asarray(d.information(whole, IDEAL_READOUT, arw, angle_white=white, **no_gm))
    np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9 * np.abs(b).max())
    # and at any length: an hour at 5 °/s sweeps 10 000° electrical (Gauss–Legendre along it,
    # 64 nodes, was 10 % off); it carries the information of its ten 6-min pieces
    hour = {**rot, "duration_s": 3600.0}
    step = -k_e * rot["rate_dps"] * 360.0
    tenths = d.BenchPlan.from_segments(
        [{**hour, "duration_s": 360.0, "wave_angle_deg": hour["wave_angle_deg"] + i * step}
         for i in range(10)]
    )  # fmt: skip
    a = np.asarray(d.information(tenths, IDEAL_READOUT, arw, angle_white=white, **no_gm))
    b = np.asarray(d.information(d.BenchPlan.from_segments([hour]), IDEAL_READOUT, arw,
                                 angle_white=white, **no_gm))  # fmt: skip
    np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9 * np.abs(b).max())
    # a ramp that turns: an hour's warm-up at 5 °/s, −40 → +20 °C, carries the information
    # of its sixty 1-min pieces (166° electrical each, one panel each; the hour takes 57
    # panels — one, as before, was 29 % off)
    warm = {"kind": "ramp", "temperature_start_c": -40.0, "temperature_end_c": 20.0,
            "wave_angle_deg": 30.0, "rate_dps": 5.0, "duration_s": 3600.0}  # fmt: skip
    k_e = float(d.nominal_values()[0])
    pieces = d.BenchPlan.from_segments(
        [{**warm, "temperature_start_c": -40.0 + i, "temperature_end_c": -39.0 + i,
          "wave_angle_deg": 30.0 - k_e * 5.0 * 60.0 * i, "duration_s": 60.0} for i in range(60)]
    )  # fmt: skip
    assert ramp_panels(pieces) is None
    a = np.asarray(d.information(pieces, **no_gm))
    b = np.asarray(d.information(d.BenchPlan.from_segments([warm]), **no_gm))
    scale = np.sqrt(np.outer(np.diag(b), np.diag(b)))
    np.testing.assert_allclose(a / scale, b / scale, rtol=0, atol=1e-9)
    # the panels are counted from the plan's numbers, which `jax.grad` carries (`jit` not)
    counted = []
    jax.grad(lambda p: counted.append(ramp_panels(p)) or 0.0)(pieces)
    jax.grad(lambda p: counted.append(ramp_panels(p)) or 0.0)(d.BenchPlan.from_segments([warm]))
    jax.jit(lambda p: counted.append(ramp_panels(p)) or 0.0)(d.BenchPlan.from_segments([warm]))
    assert counted == [None, (57,), None]
    mixed = d.BenchPlan.from_segments(SEGMENTS)
    alone = sum(np.asarray(d.information(d.BenchPlan.from_segments([s]))) for s in SEGMENTS)
    total = np.asarray(d.information(mixed))
    np.testing.assert_allclose(total, alone, rtol=1e-12, atol=1e-12 * np.abs(total).max())


@pytest.mark.parametrize("dur", [60.0, 600.0, 6000.0])
def test_a_gauss_markov_rate_limits_what_a_long_dwell_tells_the_bias(dur):
    """With a Gauss–Markov rate (σ, τ) on the pattern rate, a static segment informs the bias
    as k_e² / (var(slope) + V(D)), V(D) = (2/D²) ∫₀ᴰ (D − u) σ² e^(−u/τ) du the variance of
    the GM rate's mean (here by the trapezoid rule on a fine grid), var(slope) the exact
    least-squares slope variance of the white noises."""
    arw, sigma, tau = 1e-5, 3e-7, 600.0
    plan = d.BenchPlan.from_segments([{**SEGMENTS[0], "duration_s": dur}])
    info = np.asarray(
        d.information(plan, IDEAL_READOUT, arw, gauss_markov=(sigma, tau), angle_white=0.0)
    )
    u = np.linspace(0.0, dur, 200_001)
    f = (dur - u) * sigma**2 * np.exp(-u / tau)
    v = 2.0 / dur**2 * np.sum((f[1:] + f[:-1]) / 2 * np.diff(u))
    k_e = float(IDEAL_READOUT[0])
    var = ols_slope_variance(round(dur) + 1, 1.0, arw, 0.0)
    assert info[2, 2] == pytest.approx(k_e**2 / (var + v), rel=1e-8)
    # and the longer the dwell, the more of its white-noise information the GM rate takes
    assert info[2, 2] < k_e**2 / var


@pytest.fixture(scope="module")
def small_plan():
    segs = [{**SEGMENTS[0], "duration_s": 600.0}, {**SEGMENTS[1], "duration_s": 120.0},
            {**SEGMENTS[2], "temperature_end_c": 40.0, "duration_s": 3600.0},
            {**SEGMENTS[0], "temperature_c": 60.0, "wave_angle_deg": 60.0, "duration_s": 600.0}]  # fmt: skip
    return d.BenchPlan.from_segments(segs)


def test_criterion_gradient_equals_finite_differences(small_plan, kind="drift"):
    """jax.grad of the criterion w.r.t. the plan (jitted) = central differences (h = 0.01; rel 1e-5
    of each entry or 1e-6 of the field's largest) in every temperature, wave angle and
    duration (a static segment's two temperatures move together). A prior of one typical
    uncertainty keeps the posterior well conditioned: the differences then resolve 1e-6."""
    f = lambda p: float(d.criterion(p, kind, prior_scale=1.0))
    # under jax.jit, with the default gyro's values and noise (constants of the program)
    g = jax.jit(jax.grad(lambda p: d.criterion(p, kind, prior_scale=1.0)))(small_plan)

    def moved(field, i, h):
        p = small_plan
        p = eqx.tree_at(lambda q: getattr(q, field), p, getattr(p, field).at[i].add(h))
        if field == "temperature_c" and p.kind[i] != "ramp":
            p = eqx.tree_at(lambda q: q.temperature_end_c, p, p.temperature_end_c.at[i].add(h))
        return p

    h = 0.01
    for field in ("temperature_c", "wave_angle_deg", "duration_s"):
        got = np.asarray(getattr(g, field))
        if field == "temperature_c":
            static = np.array([k != "ramp" for k in small_plan.kind])
            got = got + np.where(static, np.asarray(g.temperature_end_c), 0.0)
        for i in range(small_plan.size):
            fd = (f(moved(field, i, h)) - f(moved(field, i, -h))) / (2 * h)
            tol = 1e-5 * abs(fd) + 1e-6 * np.abs(got).max()
            assert abs(got[i] - fd) <= tol, (field, i, got[i], fd)


def test_criteria_are_the_posterior_written_out_and_repeating_a_plan_halves_the_variance():
    """d, a and drift equal log det, trace and the grid RMS of (F + Λ)⁻¹ formed in numpy
    from `information`; the posterior covariance is that inverse; a plan run twice has
    twice the information, and with a negligible prior its drift error is 1/√2 (the seed's
    quick plan identifies all twelve parameters); the information summed in chunks (a
    concrete plan) is the traced plan's."""
    scale = np.asarray(d.GREY_BOX.scale())  # each parameter's typical uncertainty
    plan = d.seed_bench_plan(quick=True)
    f = np.asarray(d.information(plan))
    a = f * scale[:, None] * scale[None, :] + np.eye(12) / 100.0**2
    inv = np.linalg.inv(a)
    assert float(d.criterion(plan, "d")) == pytest.approx(np.linalg.slogdet(inv)[1], rel=1e-9)
    with CompileCounter() as first:  # the A criterion's program (its first use in this file)
        assert float(d.criterion(plan, "a")) == pytest.approx(np.trace(inv), rel=1e-7)
    assert "jit(evaluate_criterion)" in first.names
    cov = np.asarray(d.posterior_covariance(plan))
    np.testing.assert_allclose(cov, inv * scale[:, None] * scale[None, :], rtol=1e-6,
                               atol=1e-9 * np.abs(cov).max())  # fmt: skip
    fields = (plan.temperature_c, plan.temperature_end_c, plan.wave_angle_deg, plan.rate_dps,
              plan.duration_s)  # fmt: skip
    twice = d.BenchPlan(plan.kind * 2, *(jnp.concatenate([x, x]) for x in fields))
    np.testing.assert_allclose(
        d.information(twice), 2 * f, rtol=1e-12, atol=1e-12 * np.abs(f).max()
    )
    wide = dict(prior_scale=1e6)
    one, two = (float(d.criterion(p, "drift", **wide)) for p in (plan, twice))
    # a concrete plan's information is summed in fixed-size chunks of points (every plan
    # meets one compiled Jacobian, every criterion one program): a plan of a new structure
    # (the first 40 segments) compiles neither again; a traced plan's (jit) is the same.
    part = d.BenchPlan(plan.kind[:40], *(x[:40] for x in fields))
    with CompileCounter() as c:
        assert np.isfinite(float(d.criterion(part, "a")))
    assert not {"jit(_weighted_information)", "jit(evaluate_criterion)"} & set(c.names), c.names
    # the 40 segments leave directions unseen: beyond ≈ 1e6 the prior is below float64's
    # resolution of F (its Cholesky factor was round-off, NaN at 1e8); floored there, the
    # criterion stays finite, grows with the prior, and reads as the floor beyond it
    # (the prior's scale is an argument of the compiled criterion: a sweep compiles nothing)
    with CompileCounter() as c:
        widening = [float(d.criterion(part, "a", prior_scale=s)) for s in (1e4, 1e8, 1e12)]
    assert "jit(evaluate_criterion)" not in c.names, c.names
    assert np.all(np.isfinite(widening)) and widening[0] < widening[1], widening
    assert widening[2] == pytest.approx(widening[1], rel=1e-6)
    for bad in (0.0, -1.0, np.inf, True, [1.0, 2.0]):
        with pytest.raises(ValueError, match=r"^prior_scale must be a finite number > 0"):
            d.criterion(part, "a", prior_scale=bad)
    with pytest.raises(ValueError, match=r"^temperatures_c must be a non-empty sequence"):
        d.drift_error(part, temperatures_c=[])
    np.testing.assert_allclose(jax.jit(d.information)(plan), f, rtol=1e-12,
                               atol=1e-12 * np.abs(f).max())  # fmt: skip
    assert two / one == pytest.approx(2**-0.5, rel=1e-6)


def test_design_refuses_a_bad_argument_in_one_line_before_compiling():
    """`design`'s arguments are refused in one line naming the argument, before any search:
    a bool is not a number of hours, steps or a learning rate, and 1.5 static segments or 2.7
    levels are not read as 1 or 2 (before: `True` ran a 1-h design, 1.5 statics raised
    "can't multiply sequence by non-int", 2.7 levels ran 2, a bench "x" an AttributeError)."""
    for bad in (dict(learning_rate=True), dict(steps=True), dict(statics=1.5),
                dict(statics=True), dict(rotations=0.5), dict(rotations=-1),
                dict(levels=(2.7,)), dict(levels=()), dict(levels=3)):  # fmt: skip
        with pytest.raises(ValueError, match=f"^{next(iter(bad))} must be"):
            d.design(2.5, **{"levels": (2,), **bad})
    with pytest.raises(ValueError, match="^budget_h must be a positive number of hours; got True"):
        d.design(True, levels=(2,))
    with pytest.raises(TypeError, match="^bench must be a calibration.BenchModel"):
        d.design(2.5, levels=(2,), bench="x")
    with pytest.raises(TypeError, match="^design: key must be one JAX PRNG key"):
        d.design(2.5, levels=(2,), key=3)
    for bad in (True, "180", -1.0):  # the seed's grid with other dwells: a number of seconds
        with pytest.raises(ValueError, match="^duration_s must be a positive run length"):
            d.seed_bench_plan(duration_s=bad)


@pytest.mark.slow(
    "~60 s: compiling the search's Adam step and 40 steps of it; fast tier: the criteria "
    "and their gradient against finite differences "
    "(test_criterion_gradient_equals_finite_differences, test_warmup_criterion_…), the "
    "plan file (test_simulate_plan_file_cli)"
)
def test_design_cli_finds_a_plan_within_budget_that_beats_its_start(tmp_path, capsys):
    """`hrgjax design`: the plan it writes is within the budget (transitions included),
    loads and checks, its criterion is the one printed, and the search lowered the loss
    from its start; bad budgets are refused."""
    out, png = tmp_path / "plan.json", tmp_path / "plan.png"
    argv = ["design", "--budget-h", "2.5", "--levels", "2", "--statics", "2", "--rotations",
            "1", "--steps", "40", "--learning-rate", str(d.DEFAULT_LEARNING_RATE), "--out", str(out),
            "--plot", str(png)]  # fmt: skip
    with CompileCounter() as c:
        assert main(argv) == 0
    # one Adam-step program per structure: a weakly typed start compiled it twice (0 where
    # an earlier test in this process compiled the same structure)
    assert c.names.count("jit(_design_step)") <= 1, c.names
    text = capsys.readouterr().out
    plan, bench = d.load_plan(out)
    bench.check(plan)
    assert float(d.bench_time_h(plan, bench)) <= 2.5 + 1e-9
    assert plan.kind == ("static", "static", "rotation", "ramp", "static", "static", "rotation")
    # rounded for the bench: whole seconds (a bench and simulate_plan's whole output
    # intervals run it as written), 0.1 °C, 0.1° electrical within (−90°, 90°]
    dur = np.asarray(plan.duration_s)
    assert np.array_equal(dur, np.round(dur)) and dur.min() >= d.MIN_STATIC_S
    angles = np.asarray(plan.wave_angle_deg)
    assert np.all((angles > -90.0) & (angles <= 90.0)) and _on_grid(angles, 0.1)
    assert _on_grid(plan.temperature_c, 0.1) and _on_grid(plan.temperature_end_c, 0.1)
    value, drift, warm = (float(v) for v in d.drift_warmup_error(plan, terms=True))
    hours = float(d.bench_time_h(plan, bench))
    assert (f"{'designed':10s} {hours:6.2f} h  drift+warmup {value:.4g} ° "
            f"(drift {drift:.4g} °/h, warm-up tilt {warm:.4g} °)") in text  # fmt: skip
    # both criteria printed and stored: the search's plan and the plan as rounded (this one)
    doc = json.loads(out.read_text(encoding="utf-8"))
    crit = doc["criterion"]
    assert crit["kind"] == "drift+warmup" and crit["unit"] == "°"
    assert crit["rounded"] == pytest.approx(value, rel=1e-9)
    assert f"{crit['optimised']:.6g} ° optimised → {crit['rounded']:.6g} ° as rounded" in text
    assert doc["resolution"] == {"temperature_c": 0.1, "wave_angle_deg": 0.1, "duration_s": 1.0,
                                 "rate_dps": 0.01}  # fmt: skip
    assert doc["bench_time_h"] == hours  # of the rounded plan
    # the default criterion does not see 180° of wave angle (what the wrap relies on)
    turned = eqx.tree_at(lambda q: q.wave_angle_deg, plan, plan.wave_angle_deg + 180.0)
    assert float(d.criterion(turned)) == pytest.approx(value, rel=1e-11)
    assert png.stat().st_size > 0
    result = d.design(2.5, levels=(2,), statics=2, rotations=1, steps=40)
    assert result.history[-1] < result.history[0] - 0.1  # log-criterion fell by > 10 %
    assert result.value == pytest.approx(value, rel=1e-9)  # deterministic for a key
    assert result.optimised_value == pytest.approx(crit["optimised"], rel=1e-9)
    assert result.optimised_value == pytest.approx(
        float(d.criterion(result.optimised_plan)), rel=1e-9
    )
    assert abs(result.value / result.optimised_value - 1.0) < 0.01  # the bench's resolution
    with CompileCounter() as c:  # the learning rate and the bench's numbers are values (as
        # Python floats each new one compiled the step again, ≈ 9 s)
        d.design(2.5, levels=(2,), statics=2, rotations=1, steps=40, learning_rate=0.05,
                 bench=d.BenchModel(settle_s=1700.0, slew_c_per_min=1.5))  # fmt: skip
    assert c.compiles == 0, c.names
    for bad in (dict(learning_rate=-0.1), dict(learning_rate=float("nan")), dict(steps=0)):
        with pytest.raises(ValueError, match=f"^{next(iter(bad))} must be"):
            d.design(2.5, levels=(2,), **bad)
    with pytest.raises(ValueError, match="budget_h=0.5 cannot hold this structure"):
        d.design(0.5, levels=(2,), statics=2, rotations=1, steps=2)
    cli_fails(["design", "--budget-h", "-1"], capsys, r"--budget-h: expected a number > 0")
    cli_fails(["design", "--budget-h", "2", "--learning-rate", "0"], capsys,
              r"--learning-rate: expected a number > 0")  # fmt: skip
    for option in ("--temperature-step", "--angle-step", "--time-step", "--rate-step"):
        cli_fails(["design", "--budget-h", "2", option, "0"], capsys,
                  rf"{option}: expected a number > 0; got 0")  # fmt: skip


def test_ins_criterion_is_the_schuler_response_to_the_posterior_integrated_by_diffrax():
    """The `ins` criterion against a second method: the compensated rate error of each level
    gyro per unit error of each grey-box parameter along the warm-up flight (T(t) and Ṫ(t)
    sampled every 5 s, h = ∂(measured rate)/∂values / k_e) drives `schuler_errors` (diffrax,
    linear interpolation) — its end positions are M's entries (rel 1e-4); and
    √tr(M C Mᵀ) with C = `posterior_covariance` is the criterion (rel 1e-4); over several
    flights it is the RMS of the flights' errors (the default: the three warm-up flights,
    whose sensitivity rows are each flight's own). A measuring
    ramp only adds information, so it lowers the error (the gradient is `information`'s,
    checked against finite differences above, through a constant M)."""
    from hrgjax.calibration.ins_impact import schuler_errors
    from hrgjax.units import DEG

    plan = d.seed_bench_plan(quick=True)
    flight = d.INS_FLIGHTS[0]
    values = d.nominal_values()
    t = np.arange(0.0, flight.duration_s + 1e-9, 5.0)
    temp = flight.temperature(t)
    temp_rate = -(flight.temperature_start_c - flight.temperature_end_c) / flight.warmup_s
    temp_rate = temp_rate * np.exp(-t / flight.warmup_s)
    rate = lambda v, th, tc, tr: d.measured_rate(v, th, tc, 0.0, tr) / values[0]
    h = jax.jit(jax.vmap(jax.grad(rate), in_axes=(None, 0, 0, 0)))
    ends = []
    for angle in (flight.wave_angle_x_deg, flight.wave_angle_y_deg):
        hs = np.asarray(h(values, jnp.full(t.shape, angle * DEG), jnp.asarray(temp),
                          jnp.asarray(temp_rate)))  # fmt: skip
        zero = jnp.zeros(t.shape)
        ends.append([float(schuler_errors(jnp.asarray(t), jnp.asarray(col), zero)[1][-1, 0])
                     for col in hs.T])  # fmt: skip
    m_ode = np.asarray(ends)  # (2, P): the east channel of a north-axis error, per parameter
    m = np.asarray(d.ins_sensitivity(values, flight))
    np.testing.assert_allclose(np.abs(m_ode), np.abs(m), rtol=1e-4, atol=1e-4 * np.abs(m).max())
    cov = np.asarray(d.posterior_covariance(plan))
    predicted = np.sqrt(np.trace(m_ode @ cov @ m_ode.T)) / 1000.0
    value = float(d.criterion(plan, "ins", flight=flight))
    assert value == pytest.approx(predicted, rel=1e-4)
    assert 0.05 < value < 5.0  # km: the seed plan's calibration, a 1-h flight
    m_all = np.asarray(d.ins_sensitivity(values))  # default: the three flights, 6 rows
    assert m_all.shape == (6, m.shape[1])
    np.testing.assert_allclose(m_all[:2], m, rtol=1e-12)
    per = [np.trace(m_all[i : i + 2] @ cov @ m_all[i : i + 2].T) for i in (0, 2, 4)]
    default = float(d.criterion(plan, "ins"))
    assert default == pytest.approx(np.sqrt(np.mean(per)) / 1000.0, rel=1e-4)
    # a flight is data, not structure: another heading, pair of angles and warm-up (one
    # flight, as above) is the third flight's rows and compiles nothing new
    with CompileCounter() as c:
        third = float(d.criterion(plan, "ins", flight=d.INS_FLIGHTS[2]))
    assert third == pytest.approx(np.sqrt(per[2]) / 1000.0, rel=1e-4)
    assert not {"jit(evaluate_criterion)", "jit(_ins_sensitivity)"} & set(c.names), c.names

    ramp = {"kind": "ramp", "temperature_start_c": -40.0, "temperature_end_c": 60.0,
            "wave_angle_deg": 30.0, "duration_s": 6000.0}  # fmt: skip
    more = d.BenchPlan.from_segments(plan.segments() + [ramp])
    assert float(d.criterion(more, "ins")) < default
    with pytest.raises(TypeError, match="flight must be an ins_impact.Flight .* got str"):
        d.criterion(plan, "ins", flight="1h")
    with pytest.raises(TypeError, match="flight must be an ins_impact.Flight .* got empty"):
        d.criterion(plan, "ins", flight=())
    for bad in (0, 2.5, True):
        with pytest.raises(ValueError, match="nodes must be a positive integer"):
            d.ins_sensitivity(values, flight, nodes=bad)


def test_warmup_criterion_is_the_integrated_rate_error_and_the_default_adds_the_drift():
    """`warmup`: m = ∫ h(t) dt over the flight against the trapezoid rule on 1-s samples
    (rel 1e-6; the Ṫ term is s_T·Ṫ, the ramp's own contribution); in a chamber held at one
    temperature it is L·h(T) exactly; the criterion is √(tr(m C mᵀ) / 2) [°] (rel 1e-6), and
    the default `drift+warmup` = √((drift · 1 h)² + warmup²) (rel 1e-9). A measuring ramp
    lowers the warm-up error."""
    from hrgjax.calibration.ins_impact import Flight
    from hrgjax.units import DEG

    plan = d.seed_bench_plan(quick=True)
    flight = d.INS_FLIGHTS[1]
    values = d.nominal_values()
    t = np.arange(0.0, flight.duration_s + 1e-9, 1.0)
    rate = lambda v, th, tc, tr: d.measured_rate(v, th, tc, 0.0, tr) / values[0]
    h = jax.jit(jax.vmap(jax.grad(rate), in_axes=(None, 0, 0, 0)))
    rows = []
    for angle in (flight.wave_angle_x_deg, flight.wave_angle_y_deg):
        hs = np.asarray(h(values, jnp.full(t.shape, angle * DEG), jnp.asarray(flight.temperature(t)),
                          jnp.asarray(flight.temperature_rate(t))))  # fmt: skip
        rows.append(np.trapezoid(hs, t, axis=0))
    m_ref = np.asarray(rows)
    m = np.asarray(d.warmup_sensitivity(values, flight))
    np.testing.assert_allclose(m, m_ref, rtol=1e-6, atol=1e-6 * np.abs(m_ref).max())

    held = Flight(temperature_start_c=20.0, temperature_end_c=20.0)
    m_held = np.asarray(d.warmup_sensitivity(values, held))
    h20 = np.asarray(h(values, jnp.asarray([held.wave_angle_x_deg * DEG]), jnp.asarray([20.0]),
                       jnp.asarray([0.0])))[0]  # fmt: skip
    np.testing.assert_allclose(m_held[0], held.duration_s * h20, rtol=1e-12,
                               atol=1e-12 * np.abs(h20).max() * held.duration_s)  # fmt: skip

    cov = np.asarray(d.posterior_covariance(plan))
    warm = float(d.criterion(plan, "warmup", flight=flight))
    assert warm == pytest.approx(np.sqrt(np.trace(m @ cov @ m.T) / 2) / DEG, rel=1e-6)
    both = float(d.criterion(plan, flight=flight))  # the default kind
    drift = float(d.criterion(plan, "drift"))
    assert both == pytest.approx(np.hypot(drift * flight.duration_s / 3600.0, warm), rel=1e-9)
    terms = [float(v) for v in d.drift_warmup_error(plan, flight=flight, terms=True)]
    np.testing.assert_allclose(terms, [both, drift, warm], rtol=1e-12)
    ramp = {"kind": "ramp", "temperature_start_c": -40.0, "temperature_end_c": 60.0,
            "wave_angle_deg": 30.0, "duration_s": 6000.0}  # fmt: skip
    more = d.BenchPlan.from_segments(plan.segments() + [ramp])
    assert float(d.criterion(more, "warmup", flight=flight)) < warm


_RATE_JACOBIAN = jax.jit(jax.vmap(jax.jacfwd(d.measured_rate), in_axes=(None, 0, None, None, None)))
"""∂(measured rate)/∂values along a path of wave angles: one program for every call below."""


def _window_slope_information(rate_dps, angles, duration, n=20, dt=0.5, fine=0.05):
    """Fisher information of rotations at `rate_dps` from `angles` [°] as the physical fit
    sees them, written out: ∂θ̂/∂p integrated along the path (trapezoid, `fine` [s]), the
    least-squares slope of each consecutive window of `n` samples `dt` [s] apart (a
    rotation's: 20 × 0.5 s; a ramp's: 10 × 1 s), 1/slope variance each."""
    from hrgjax.pattern_noise import slope_variance
    from hrgjax.units import DEG, DEG_PER_S

    values = d.nominal_values()
    k_e, om = float(values[0]), rate_dps * DEG_PER_S
    var = float(slope_variance(d.pattern_angle_white(), d.pattern_arw(), n, dt))
    t = np.arange(0.0, duration + 1e-9, fine)
    total = np.zeros((values.size, values.size))
    for a0 in angles:
        g = np.asarray(_RATE_JACOBIAN(values, jnp.asarray(a0 * DEG - k_e * om * t), 20.0, om, 0.0))
        cum = np.concatenate([np.zeros((1, g.shape[1])),
                              np.cumsum(0.5 * (g[1:] + g[:-1]) * fine, axis=0)])  # fmt: skip
        for w0 in np.arange(0.0, duration - n * dt + 1e-9, n * dt):
            ts = w0 + dt * np.arange(n)
            c = (ts - ts.mean()) / np.sum((ts - ts.mean()) ** 2)
            s = c @ cum[np.rint(ts / fine).astype(int)]
            total += np.outer(s, s) / var
    return total


def test_a_rotation_informs_only_through_its_window_slopes():
    """The fit sees a rotation only through its 10-s window slopes: at 40 °/s a window sweeps
    222° electrical and the 2θ ripple that carries Δ(1/τ)₀, θ_τ0, gain_mismatch0 and
    cross_talk averages out of every slope. `information` equals the window slopes' Fisher
    information written out (averaged over four wave angles 45° apart, which cancels where
    the windows happen to fall) at 5, 20 and 40 °/s — it counted the pointwise rate, 1.05,
    2.2 and 73× too much; the traced program (`jit`, the design search's) agrees, and so does
    a turning ramp at a held temperature with its own windows (10 samples 1 s apart)."""
    angles, duration = (0.0, 45.0, 90.0, 135.0), 40.0
    seen = [0, 2, 5, 7, 9, 11]  # a rotation at one temperature sees these (k_e, bias, 2θ)
    for rate in (5.0, 20.0, 40.0):
        segs = [{"kind": "rotation", "temperature_c": 20.0, "wave_angle_deg": a,
                 "rate_dps": rate, "duration_s": duration} for a in angles]  # fmt: skip
        plan = d.BenchPlan.from_segments(segs)
        lib = np.asarray(d.information(plan, gauss_markov=(0.0, 1.0)))
        ref = _window_slope_information(rate, angles, duration)
        np.testing.assert_allclose(np.diag(lib)[seen], np.diag(ref)[seen], rtol=0.01)
    traced = jax.jit(lambda p: d.information(p, gauss_markov=(0.0, 1.0)))(plan)
    np.testing.assert_allclose(np.diag(traced)[seen], np.diag(lib)[seen], rtol=1e-9)
    ramps = d.BenchPlan.from_segments([
        {"kind": "ramp", "temperature_start_c": 20.0, "temperature_end_c": 20.0 + 1e-6,
         "wave_angle_deg": a, "rate_dps": 40.0, "duration_s": duration} for a in angles])  # fmt: skip
    turning = np.asarray(d.information(ramps, gauss_markov=(0.0, 1.0)))
    ref = _window_slope_information(40.0, angles, duration, n=10, dt=1.0)
    np.testing.assert_allclose(np.diag(turning)[seen], np.diag(ref)[seen], rtol=0.01)


def test_a_bad_linearisation_point_is_named():
    """`values` is checked where it enters every criterion and the design search: a NaN, a
    k_e ≤ 0 (both NaN criteria before) or a wrong length (a raw broadcasting error) is one
    ValueError naming `values`; the traced (`jit`) path checks the shape."""
    plan = d.BenchPlan.from_segments(SEGMENTS)
    v = np.asarray(d.nominal_values())
    nan, zero = v.copy(), v.copy()
    nan[3], zero[0] = np.nan, 0.0
    for bad, what in ((nan, "nan at index 3"), (zero, "k_e = 0.0"), (np.ones(5), "shape (5,)")):
        for call in (lambda x: d.criterion(plan, "drift", values=x),
                     lambda x: d.information(plan, values=x),
                     lambda x: d.posterior_covariance(plan, values=x)):  # fmt: skip
            with pytest.raises(
                ValueError, match=r"values must be 12 finite numbers.*" + re.escape(what)
            ):
                call(bad)
    with pytest.raises(ValueError, match="values must be 12 finite"):
        d.design(4.0, levels=(2,), statics=1, rotations=1, steps=1, values=nan)
    with pytest.raises(ValueError, match=r"values must be .* shape \(5,\)"):
        jax.jit(lambda x: d.criterion(plan, "drift", values=x))(jnp.ones(5))
    with pytest.raises(ValueError, match=r"values must be 90 finite numbers in the empirical"):
        d.criterion(plan, "drift", model="empirical", values=np.ones(12))


def test_a_ramp_faster_than_its_bench_is_neither_written_nor_read_and_costs_the_chambers_time(
    tmp_path,
):
    """100 °C in 10 s on a 1 °C/min chamber: `save_plan`, `plan_to_json` and `load_plan`
    refuse it with `BenchModel.check`'s message (the file carries its bench), and a plan
    built in Python — which does not know its bench — is charged the chamber's 6000 s for
    it (it read 1.59 h, less than the 1.67 h of slewing alone)."""
    fast = d.BenchPlan.from_segments([
        {**SEGMENTS[0], "temperature_c": -40.0},
        {**SEGMENTS[2], "temperature_start_c": -40.0, "temperature_end_c": 60.0,
         "duration_s": 10.0}])  # fmt: skip
    bench = d.BenchModel()
    message = r"segment 1 \(ramp\): 600 °C/min is faster than the chamber's slew_c_per_min=1"
    with pytest.raises(ValueError, match=message):
        d.save_plan(fast, tmp_path / "fast.json", bench)
    with pytest.raises(ValueError, match=message):
        d.plan_to_json(fast)
    assert not (tmp_path / "fast.json").exists()
    f = tmp_path / "hand.json"
    f.write_text(json.dumps({"segments": fast.segments(), "bench": bench.to_json()}))
    with pytest.raises(ValueError, match="hand.json: " + message):
        d.load_plan(f)
    slow = eqx.tree_at(lambda p: p.duration_s, fast, fast.duration_s.at[1].set(6000.0))
    assert float(d.bench_time_h(fast, bench)) == pytest.approx(
        float(d.bench_time_h(slow, bench)), rel=1e-12
    )
    parts = bench.breakdown_h(fast)
    assert parts["slew"] == pytest.approx(60.0 / 60.0 + (6000.0 - 10.0) / 3600.0, rel=1e-12)
    assert parts["total"] == pytest.approx(float(d.bench_time_h(fast, bench)), rel=1e-12)
    # a ramp the chamber can run is charged its duration, as before (gradient unchanged)
    assert float(bench.ramp_overrun_s(slow)[1]) == 0.0
    slope = float(jax.grad(lambda p: d.bench_time_h(p, bench))(slow).duration_s[1])
    assert slope == pytest.approx(1 / 3600, rel=1e-12)


def test_information_counts_the_windows_the_reduction_forms():
    """Each segment's windows as `information` counts them equal those `reduce` forms of its
    samples (10-s windows of a rotation, a static whole): a rotation shorter than a window
    is one window of its own samples (not a full 10-s one), and a segment of fewer than 6
    samples — which `reduce` refuses (3 batches of 2 for its standard error) — teaches
    nothing (a 0.5-s static and a 0.7-s rotation added 2.7e9 and 1.9e11 to F's trace)."""
    from hrgjax.calibration import reduce
    from hrgjax.calibration._information import segment_windows
    from hrgjax.calibration.physical import PhysicalCompensator

    rot = SEGMENTS[1]
    segs = [{**SEGMENTS[0], "duration_s": 5.0}, SEGMENTS[0], {**rot, "duration_s": 5.0},
            {**rot, "duration_s": 9.5}, {**rot, "duration_s": 30.0},
            {**SEGMENTS[2], "temperature_end_c": -20.0, "rate_dps": 5.0, "duration_s": 20.0}]  # fmt: skip
    plan = d.BenchPlan.from_segments(segs)
    dts = [d.DT_OUT[k] for k in plan.kind]
    times = [
        np.arange(round(s["duration_s"] / dt) + 1) * dt for s, dt in zip(segs, dts, strict=True)
    ]
    data = hg.MeasuredData({
        "time_s": np.concatenate(times),
        "run": np.concatenate([np.full(t.size, i) for i, t in enumerate(times)]),
        "temperature_c": np.concatenate([np.full(t.size, -20.0) for t in times]),
        "table_rate_dps": np.concatenate([np.full(t.size, s.get("rate_dps", 0.0))
                                          for s, t in zip(segs, times, strict=True)]),
        "wave_angle_deg": np.concatenate([-0.6 * s.get("rate_dps", 0.0) * t
                                          for s, t in zip(segs, times, strict=True)])})  # fmt: skip
    win = reduce(data, window_s=PhysicalCompensator.window_s)
    counted = segment_windows(plan)
    for i in range(plan.size):
        mine = win.run == i
        n = np.round(win.duration[mine] / dts[i]) + 1  # samples of each window
        assert counted[i] == (n[0], mine.sum()), (i, counted[i], n, mine.sum())
    base = d.BenchPlan.from_segments([SEGMENTS[0]])
    before = np.asarray(d.information(base))
    for short in ({**SEGMENTS[0], "duration_s": 0.5}, {**SEGMENTS[0], "duration_s": 4.0},
                  {**rot, "duration_s": 0.7}, {**rot, "duration_s": 2.0}):  # fmt: skip
        plan = d.BenchPlan.from_segments([SEGMENTS[0], short])
        assert segment_windows(plan)[1] == (0.0, 0.0)
        np.testing.assert_array_equal(np.asarray(d.information(plan)), before)
    with pytest.raises(ValueError, match="windows of 5 samples are too short"):
        reduce(hg.MeasuredData({k: v[:5] for k, v in data.columns.items()}))


def test_bench_time_is_one_program_per_plan_length():
    """Compile once: `bench_time_h` ran op by op (18–22 compiles on each new plan length);
    one program per length now, whatever the order of kinds, and differentiable."""
    seg = lambda t, kind="static": ({"kind": kind, "temperature_c": t, "wave_angle_deg": 0.0,
                                     "duration_s": 30.0} | ({"rate_dps": 2.0} if kind ==
                                                            "rotation" else {}))  # fmt: skip
    plan = d.BenchPlan.from_segments([seg(5.0 * k) for k in range(7)])
    with CompileCounter() as c:
        d.bench_time_h(plan)
    assert c.compiles <= 1, c.names
    other = d.BenchPlan.from_segments([seg(3.0 * k, ("rotation", "static")[k % 2])
                                       for k in range(7)])  # fmt: skip
    with CompileCounter() as c:
        h = d.bench_time_h(other, d.BenchModel(settle_s=600.0))
    assert c.compiles == 0, c.names
    assert float(h) * 3600 == pytest.approx(float(d.BenchModel(settle_s=600.0).bench_time_s(other)))
    g = jax.grad(d.bench_time_h)(plan)
    np.testing.assert_allclose(g.duration_s, 1 / 3600, rtol=1e-15)
    # a bench's numbers are float64 array leaves: values, not constants, of the programs
    # eqx.filter_jit compiles (`design`'s step: a Python float there compiled it again);
    # written as plain floats
    bench = d.BenchModel(settle_s=1700, slew_c_per_min=1.5)
    assert all(eqx.is_array(x) and x.dtype == np.float64 for x in jax.tree.leaves(bench))
    assert bench.to_json()["settle_s"] == 1700.0 and type(bench.to_json()["settle_s"]) is float
    # and it still hashes and prints as its numbers (review: NumPy leaves are unhashable)
    assert (
        hash(bench)
        == hash(d.BenchModel(settle_s=1700.0, slew_c_per_min=1.5))
        != hash(d.BenchModel())
    )
    assert "settle_s=1700.0" in repr(bench)


def test_noise_arguments_are_checked_as_hg_noise_checks_them():
    """Audit: `criterion(plan, "drift", angle_white=1.0)` (1″ typed as 1 rad) returned 3.55 °/h,
    `arw=0.01` and `gauss_markov=(0.05, 600)` (datasheet units as SI) too, and a bad τ was
    reported as "arw must be > 0". Each is refused in one line naming the argument, with
    `hg.Noise`'s ranges and unit hints; traced values pass (the design differentiates them)."""
    from hrgjax.calibration._models import noise_vector

    plan = d.BenchPlan.from_segments([SEGMENTS[0]])
    for kw, match in (
        ({"angle_white": 1.0}, r"^angle_white = 1 is outside the plausible range 0 … 0.1 rad "
         r"electrical — ″ → ×hrgjax.units.ARCSEC"),
        ({"arw": 0.01}, r"^arw = 0.01 is outside the plausible range 0 … 0.001 rad/√s — °/√h"),
        ({"gauss_markov": (0.05, 600.0)}, r"^gauss_markov σ = 0.05 is outside the plausible "
         r"range 0 … 0.001 rad/s — °/h → ×hrgjax.units.DEG_PER_H"),
        ({"gauss_markov": (1e-7, 0.0)}, r"^gauss_markov τ must be a finite number > 0 \[s\]"),
        ({"arw": -1e-6}, r"^arw must be a finite number > 0 \[rad/√s\]; got -1e-06"),
        ({"angle_white": np.nan}, r"^angle_white must be a finite number ≥ 0"),
        ({"gauss_markov": 1e-7}, r"^gauss_markov must be a pair \(σ \[rad/s\], τ \[s\]\)"),
        ({"arw": "1e-6"}, r"^arw must be a single real number \[rad/√s\]; got str"),
    ):  # fmt: skip
        with pytest.raises((ValueError, TypeError), match=match) as err:
            d.criterion(plan, "drift", **kw)
        assert "\n" not in str(err.value)
    noise = lambda a: noise_vector(a, (a, 600.0), a)  # noqa: E731 — 1.0 of each: implausible
    assert float(jax.grad(lambda a: noise(a).sum())(1.0)) == 3.0
    np.testing.assert_array_equal(jax.jit(noise)(1.0), [1.0, 1.0, 600.0, 1.0])


def test_plan_segments_take_numpy_and_jax_scalars():
    """Audit: `from_segments` refused np.int64(60), np.float32 and 0-d arrays ("must be a
    finite number; got np.int64(60)"): any real scalar is its number; a traced one is named."""
    base = {"kind": "static", "temperature_c": 20.0, "wave_angle_deg": 0.0, "duration_s": 60.0}
    for value in (np.int64(60), np.float32(60.0), np.array(60.0), jnp.array(60), np.arange(61)[-1]):
        plan = d.BenchPlan.from_segments([{**base, "duration_s": value}])
        assert float(plan.duration_s[0]) == 60.0
    build = lambda t: d.BenchPlan.from_segments([{**base, "temperature_c": t}])  # noqa: E731
    with pytest.raises(ValueError, match=r"^segments\[0\] \(static\): 'temperature_c' must be a "
                       r"finite number \[°C\]; got a traced value"):  # fmt: skip
        jax.jit(lambda t: build(t).duration_s)(20.0)
    with pytest.raises(ValueError, match=r"'duration_s' must be a finite number \[s\]; got bool"):
        d.BenchPlan.from_segments([{**base, "duration_s": np.True_}])
