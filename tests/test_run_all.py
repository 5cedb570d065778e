"""`benchmarks/run_all.py`: figures reported by a script reach the summary; failures and
time-outs are recorded, not lost; the summary names the device and versions."""

import importlib.util
import json
import sys
import textwrap
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parent.parent / "benchmarks"


@pytest.fixture(scope="module")
def run_all():
    spec = importlib.util.spec_from_file_location("run_all", BENCH / "run_all.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def script(tmp_path, body):
    path = tmp_path / "fake_bench.py"
    path.write_text(
        f"import sys\nsys.path.insert(0, {str(BENCH)!r})\nfrom _common import report\n"
        + textwrap.dedent(body)
    )
    return path


def test_figures_status_and_summary(run_all, tmp_path):
    ok = script(tmp_path, 'report("speed", 2.5, "ms", "a / b", 4.0, "≤ 5×")\n')
    status, figures = run_all.run(ok, ["--quick"], 120.0, tmp_path)
    assert status["status"] == "ok" and status["script"] == "fake_bench"
    assert figures == [
        {"figure": "speed", "value": 2.5, "unit": "ms", "comparison": "a / b", "ratio": 4.0,
         "target": "≤ 5×", "script": "fake_bench", "quick": True}
    ]  # fmt: skip
    assert "FIGURE speed: 2.5 ms" in (tmp_path / "fake_bench.log").read_text()

    failing = script(tmp_path, 'report("n", 1, "")\nsys.exit(3)\n')
    status, figures = run_all.run(failing, [], 120.0, tmp_path)
    assert status["status"] == "failed (exit 3)"
    assert [f["figure"] for f in figures] == ["n"]  # what it reported before failing is kept

    hanging = script(tmp_path, "import time\ntime.sleep(120)\n")
    status, figures = run_all.run(hanging, [], 1.0, tmp_path)
    assert status["status"] == "timed out after 1 s" and figures == []

    env = run_all.environment()
    assert env["device_kind"] and env["platform"] in ("cpu", "gpu", "tpu")
    assert env["versions"]["jax"] and env["versions"]["python"] == ".".join(
        map(str, sys.version_info[:3])
    )
    summary = {"environment": env, "quick": False, "scripts": [status], "figures": [
        {"figure": "speed", "value": 2.5, "unit": "ms", "comparison": "a / b", "ratio": 4.0,
         "target": "≤ 5×", "script": "fake_bench", "quick": False}]}  # fmt: skip
    md = run_all.markdown(summary)
    assert "| fake_bench | speed | 2.5 | ms | a / b | 4× | ≤ 5× |" in md
    assert "timed out after 1 s" in md
    json.dumps(summary)  # the summary is plain JSON


def test_only_names_known_scripts(run_all, capsys):
    assert "adjoint_memory" in run_all.scripts() and "run_all" not in run_all.scripts()
    with pytest.raises(SystemExit):
        run_all.main(["--only", "no_such_benchmark"])
    assert "unknown script(s) ['no_such_benchmark']" in capsys.readouterr().err
