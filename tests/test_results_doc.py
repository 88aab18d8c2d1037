"""docs/results.md is exactly what bench/results.py makes of the bench JSON in docs/results/."""
from __future__ import annotations

import json
import re
import runpy
import shutil
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "docs" / "results"
DOC = ROOT / "docs" / "results.md"
GENERATOR = runpy.run_path(str(ROOT / "bench" / "results.py"))
#: bench/*.py that are not bench scripts
HELPERS = {"facts", "results", "result_sections"}


def _generate(tmp_path, results=RESULTS) -> str:
    out = tmp_path / "results.md"
    assert GENERATOR["main"](["--results", str(results), "--out", str(out)]) == 0
    return out.read_text()


def test_committed_document_is_generated_from_the_json(tmp_path):
    assert _generate(tmp_path) == DOC.read_text(), "docs/results.md is stale: run python bench/results.py"


def test_generating_twice_gives_the_same_file(tmp_path):
    first = _generate(tmp_path)
    assert _generate(tmp_path) == first


def test_a_changed_json_value_changes_the_document(tmp_path):
    copy = tmp_path / "results"
    shutil.copytree(RESULTS, copy)
    path = copy / "fit_benchmark.json"
    data = json.loads(path.read_text())
    servo = data["results"][0]["servos"][0]
    servo["terms"] += 1000
    path.write_text(json.dumps(data))
    text = _generate(tmp_path, copy)
    assert text != DOC.read_text()
    row = next(line for line in text.splitlines() if line.startswith(f"| {data['results'][0]['preset']} | "))
    assert f" | {servo['terms']} | " in row


def test_every_bench_script_has_a_section_and_writes_into_docs_results():
    scripts = sorted(p.stem for p in (ROOT / "bench").glob("*.py") if p.stem not in HELPERS)
    assert sorted(GENERATOR["SECTIONS"]) == scripts
    for name in scripts:
        text = (ROOT / "bench" / f"{name}.py").read_text()
        assert f'FACTS["default_json"]("{name}")' in text and f'FACTS["run_facts"]("{name}", argv)' in text, name


def test_every_section_records_its_command_and_machine():
    text = DOC.read_text()
    for path in sorted(RESULTS.glob("*.json")):
        run = json.loads(path.read_text())["run"]
        assert run["command"].startswith(f"python bench/{path.stem}.py")
        assert f"- command: `{run['command']}`" in text
        assert run["platform"] in text and run["date_utc"] in text


def test_unknown_json_is_named(tmp_path):
    (tmp_path / "mystery.json").write_text("{}")
    with pytest.raises(SystemExit, match=rf"^{re.escape(str(tmp_path / 'mystery.json'))}: no section for bench "
                                         r"'mystery' \(expected one of fit_benchmark, "):
        GENERATOR["main"](["--results", str(tmp_path), "--out", str(tmp_path / "out.md")])


def test_json_without_run_record_is_refused(tmp_path):
    (tmp_path / "fit_benchmark.json").write_text(json.dumps({"results": []}))
    with pytest.raises(SystemExit, match=r"fit_benchmark\.json: expected a JSON object with a 'run' record "
                                         r"\(written by bench/facts\.py\)$"):
        GENERATOR["main"](["--results", str(tmp_path), "--out", str(tmp_path / "out.md")])


def test_json_missing_a_figure_is_named(tmp_path):
    data = json.loads((RESULTS / "fit_benchmark.json").read_text())
    del data["results"][0]["servos"][0]["terms"]
    (tmp_path / "fit_benchmark.json").write_text(json.dumps(data))
    with pytest.raises(SystemExit, match=r"^fit_benchmark\.json: cannot render its section \(KeyError: 'terms'\); "
                                         r"rerun bench/fit_benchmark\.py$"):
        GENERATOR["main"](["--results", str(tmp_path), "--out", str(tmp_path / "out.md")])


def test_fit_benchmark_merge_keeps_the_rows_of_presets_not_refitted(tmp_path):
    """``bench/fit_benchmark.py --merge``: the file's rows of other presets first, this run's
    after, and the runs the kept rows come from."""
    merge_rows = runpy.run_path(str(ROOT / "bench" / "facts.py"))["merge_rows"]
    path = tmp_path / "fit_benchmark.json"
    assert merge_rows(path, [{"preset": "a"}], "preset") == []
    path.write_text(json.dumps({"run": {"command": "first"}, "earlier_runs": [{"command": "zeroth"}],
                                "results": [{"preset": "a", "v": 1}, {"preset": "b", "v": 1}]}))
    results = [{"preset": "b", "v": 2}]
    assert merge_rows(path, results, "preset") == [{"command": "first"}, {"command": "zeroth"}]
    assert results == [{"preset": "a", "v": 1}, {"preset": "b", "v": 2}]
    assert merge_rows(path, [{"preset": "a"}, {"preset": "b"}], "preset") == []
