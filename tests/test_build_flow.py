"""The build flow: never loses a user's file, leaves nothing when interrupted, caches eval's fit,
reports certification progress, and sets BLAS threads only in the entry point."""
import json
import os
import signal
import subprocess
import sys
import textwrap

import pytest

import ikseries.buildrecord as buildrecord_mod
import ikseries.steps as steps_mod
from ikseries.build import BuildError, build, planned_outputs
from ikseries.buildrecord import RECORD_NAME, add_to_record, recorded_files
from ikseries.cli import main
from ikseries.fit.plan import Plan
from ikseries.robot import preset_text, with_hardware


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def _no_fit(*args, **kwargs):
    raise AssertionError("the build fitted before refusing")


def _copy(plan):
    return Plan.from_json(json.loads(plan.dumps()))


@pytest.fixture
def fast_fit(monkeypatch, small_fitted):
    """build() gets the session's fit of the small robot instead of fitting (a fresh copy each
    time: the build stores the robot description in the plan's meta)."""
    plan, fits = small_fitted
    monkeypatch.setattr(steps_mod, "fit_robot", lambda robot, progress, **options: (_copy(plan), fits))


@pytest.mark.parametrize("name, options", [
    ("plan.json", []),
    ("cylinder_leg_core.v", []),
    ("sim.vcd", ["--vcd"]),
    ("cocotb_icarus.log", ["--cocotb", "icarus"]),
])
def test_foreign_file_is_refused_before_the_fit(capsys, monkeypatch, tmp_path, name, options):
    monkeypatch.setattr(steps_mod, "fit_robot", _no_fit)
    out = tmp_path / "out"
    out.mkdir()
    (out / name).write_text("the user's own file")
    argv = ["build", "-q", "--no-synth", "-o", str(out), *options]
    if "--cocotb" not in options:
        argv += ["--cocotb", "none"]
    code, _, err = run(capsys, *argv)
    assert code == 1 and err == (f"ikseries: error: output directory '{out}' holds {name}, not written by an "
                                 "ikseries build there; a build would replace it: move it away or choose "
                                 "another -o\n")
    assert (out / name).read_text() == "the user's own file"
    assert sorted(p.name for p in out.iterdir()) == [name]


def test_foreign_sim_models_directory_is_refused(monkeypatch, tmp_path, small_robot):
    robot = with_hardware(small_robot, architecture="modulo", dsp="ecp5", dsp_primitives=True)
    assert "sim_models" in planned_outputs(robot, vcd=False, cocotb=[])
    assert "sim_models" not in planned_outputs(small_robot, vcd=False, cocotb=[])
    monkeypatch.setattr(steps_mod, "fit_robot", _no_fit)
    (tmp_path / "sim_models").mkdir()
    (tmp_path / "sim_models" / "mine.v").write_text("module mine; endmodule\n")
    with pytest.raises(BuildError, match=r"holds sim_models, not written by an ikseries build"):
        build(robot, tmp_path, synth=False, cocotb=[], progress=lambda m: None)
    assert (tmp_path / "sim_models" / "mine.v").is_file()


def test_corrupt_build_record_is_refused(capsys, monkeypatch, tmp_path):
    monkeypatch.setattr(steps_mod, "fit_robot", _no_fit)
    (tmp_path / RECORD_NAME).write_text('{"format": "ikseries-build-files", "files": ["../etc"]}')
    code, _, err = run(capsys, "build", "-q", "--no-synth", "--cocotb", "none", "-o", str(tmp_path))
    assert code == 1 and err.startswith(f"ikseries: error: {tmp_path / RECORD_NAME} must be an ikseries build "
                                        "record (format 'ikseries-build-files' with a list of file names)")


def test_rebuild_replaces_only_what_a_build_wrote(fast_fit, monkeypatch, tmp_path, small_robot):
    """The user's pnr.json and notes survive; the build's own sim.vcd and a recorded pnr.json
    (as ``report --pnr`` records it) go when a rebuild does not write them; the temporary
    directory is made inside the output directory, never in its parent."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "pnr.json").write_text("user pnr")
    (out / "notes.txt").write_text("user notes")
    made_in = []
    real_mkdtemp = buildrecord_mod.tempfile.mkdtemp     # the staging of every build

    def spy(*args, **kwargs):
        made_in.append(kwargs.get("dir"))
        return real_mkdtemp(*args, **kwargs)
    monkeypatch.setattr(buildrecord_mod.tempfile, "mkdtemp", spy)
    say = lambda m: None   # noqa: E731
    build(small_robot, out, synth=False, vcd=True, cocotb=[], progress=say)
    assert made_in == [out]
    names = {"cylinder_leg_small_core.v", "cylinder_leg_small_core.sdc", "plan.json", "manifest.json",
             "report.json", "report.md", "error_map.png", "sim.vcd"}
    assert recorded_files(out) == names
    assert sorted(p.name for p in out.iterdir()) == sorted(names | {RECORD_NAME, "pnr.json", "notes.txt"})
    assert (out / "pnr.json").read_text() == "user pnr"
    (out / "pnr.json").write_text("pnr of this build")       # what `ikseries report --pnr` does
    add_to_record(out, "pnr.json")
    build(small_robot, out, synth=False, vcd=False, cocotb=[], progress=say)
    assert recorded_files(out) == names - {"sim.vcd"}
    assert sorted(p.name for p in out.iterdir()) == sorted(names - {"sim.vcd"} | {RECORD_NAME, "notes.txt"})
    assert (out / "notes.txt").read_text() == "user notes"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


_INTERRUPTED = """
import sys, time
from pathlib import Path
import ikseries.steps as steps
from ikseries.cli import main
from ikseries.fit.plan import Plan
import json
plan = Plan.from_json(json.loads(Path(sys.argv[1]).read_text()))
steps.fit_robot = lambda robot, progress, **options: (plan, [])

def slow_simulation(core, plan, progress, vcd=None):
    Path(vcd).write_text("partial waveform")      # a half-written output in the temporary directory
    print("simulating", flush=True)
    time.sleep(60)
steps.simulate = slow_simulation
sys.exit(main(["build", sys.argv[2], "-q", "--no-synth", "--vcd", "--cocotb", "none", "-o", sys.argv[3]]))
"""


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_interrupted_build_leaves_nothing(tmp_path, small_plan_file, sig):
    toml = tmp_path / "small.toml"
    toml.write_text(preset_text("cylinder-leg").replace("tolerance_pu = 0.5 ", "tolerance_pu = 4.0 "))
    out = tmp_path / "new" / "out"
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    proc = subprocess.Popen([sys.executable, "-c", _INTERRUPTED, str(small_plan_file), str(toml), str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        assert proc.stdout.readline() == "simulating\n"
        assert any(p.name.startswith(".ikseries-tmp-") for p in out.iterdir())
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
    assert proc.returncode == 128 + sig and err == "ikseries: interrupted\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["small.toml"]   # new/out made and removed


def test_eval_fits_once_then_uses_the_cache(capsys, monkeypatch, tmp_path, small_fitted):
    import ikseries.fit.fitter as fitter
    calls = []

    def fit(robot, progress=None, **options):
        calls.append(robot.name)
        return _copy(small_fitted[0]), small_fitted[1]
    monkeypatch.setattr(fitter, "fit_robot", fit)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.chdir(tmp_path)
    toml = tmp_path / "leg.toml"
    toml.write_text(preset_text("cylinder-leg").replace("tolerance_pu = 0.5 ", "tolerance_pu = 4.0 "))
    code, out, _ = run(capsys, "eval", "--robot", str(toml), "-q", "10", "45", "5")
    cached = list((tmp_path / "cache" / "ikseries" / "plans").iterdir())
    assert code == 0 and calls == ["cylinder-leg"] and len(cached) == 1 and cached[0].suffix == ".json"
    assert out.splitlines()[0] == f"plan: fitted and cached in {cached[0]}"
    renamed = tmp_path / "other.toml"      # another name and architecture: the same fit
    renamed.write_text(toml.read_text().replace('name = "cylinder-leg"', 'name = "other-leg"')
                       .replace("pwm_period_us = 20000.0", 'pwm_period_us = 20000.0\narchitecture = "folded"'))
    code, out2, _ = run(capsys, "eval", "--robot", str(renamed), "-q", "10", "45", "5")
    assert code == 0 and calls == ["cylinder-leg"]
    assert out2.splitlines()[0] == f"plan: {cached[0]} (cached)"
    assert out2.splitlines()[1:] == out.splitlines()[1:]
    tighter = tmp_path / "tight.toml"      # another tolerance: another fit
    tighter.write_text(toml.read_text().replace("tolerance_pu = 4.0 ", "tolerance_pu = 3.0 "))
    code, out3, _ = run(capsys, "eval", "--robot", str(tighter), "-q", "10", "45", "5")
    assert calls == ["cylinder-leg", "cylinder-leg"] and "fitted and cached" in out3
    assert len(list((tmp_path / "cache" / "ikseries" / "plans").iterdir())) == 2


def test_certification_reports_progress(monkeypatch, small_robot, small_plan):
    import ikseries.fit.certify as certify_mod
    monkeypatch.setattr(certify_mod, "PROGRESS_SECONDS", 0.0)
    lines = []
    certify_mod.certify(small_robot, small_plan, max_cells=20_000, progress=lines.append)
    inner = [l for l in lines if "cell enclosures evaluated, max bound so far" in l]
    assert inner and all(l.startswith("  s") for l in inner)
    assert any("to split" in l and "(target " in l for l in lines)
    monkeypatch.setattr(certify_mod, "PROGRESS_SECONDS", 3600.0)
    few = []
    certify_mod.certify(small_robot, small_plan, max_cells=20_000, progress=few.append)
    assert len(few) == 2 * len(small_plan.outputs)    # per servo: the first line, then its result


def test_threads_are_set_by_main_not_by_import(monkeypatch):
    code = textwrap.dedent("""
        import os, sys
        for v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
            os.environ.pop(v, None)
        import ikseries, ikseries.cli
        print(os.environ.get("OPENBLAS_NUM_THREADS"), "numpy" in sys.modules)
        ikseries.cli.main(["presets"])
        print(os.environ.get("OPENBLAS_NUM_THREADS"), os.environ.get("MKL_NUM_THREADS"))
    """)
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    lines = res.stdout.splitlines()
    assert lines[0] == "None False" and lines[-1] == "1 1", res.stderr
