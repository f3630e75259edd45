"""docs/python-api.md's examples run as written, and the in-memory pass writes no file."""

import re
from pathlib import Path

import pytest

DOC = Path(__file__).resolve().parents[2] / "docs" / "python-api.md"
EXAMPLES = re.findall(r"```python\n(.*?)```", DOC.read_text(), flags=re.S)


def test_the_doc_has_the_two_examples():
    assert len(EXAMPLES) == 2


@pytest.mark.parametrize("code", EXAMPLES, ids=["scanner_sim", "muls"])
def test_example_runs_in_memory_without_writing_files(code, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    namespace = {}
    exec(compile(code, str(DOC), "exec"), namespace)
    assert list(tmp_path.iterdir()) == []  # nothing written, not even out/
    assert capsys.readouterr().out.strip()
    if "result" in namespace:
        result = namespace["result"]
        assert len(result.points) == result.summary["points"] > 3000
        assert result.out_dir is None and result.trajectory["time_s"].size > 0
        assert result.points_dataframe().shape[0] == len(result.points)
        assert result.points_polydata().n_points == len(result.points)
