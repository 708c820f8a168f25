"""The README's Python tour runs as written."""

import pathlib
import re

ROOT = pathlib.Path(__file__).resolve().parents[1]


def test_readme_python_snippets_run(arm):
    text = (ROOT / "README.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    assert blocks
    for code in blocks:
        exec(compile(code, "README.md", "exec"), {})


def test_readme_names_the_two_commands():
    text = (ROOT / "README.md").read_text()
    assert "pip install -e . && stmpl predict --load disk --force 0.3 --out prediction.png" in text
    assert 'pip install -e ".[test]" && python -m pytest -q' in text
    ci = (ROOT / ".ci" / "run").read_text()
    assert 'pip install -e ".[test]" && python -m pytest -q' in ci


def test_readme_main_command_runs_on_the_shipped_default(tmp_path, capsys, arm):
    from stmpl.cli import main

    assert main(["predict", "--load", "disk", "--force", "0.3",
                 "--out", str(tmp_path / "prediction.png")]) == 0
    out = capsys.readouterr().out
    assert "gnn_arm" in out and (tmp_path / "prediction.png").stat().st_size > 20_000
