"""The README's core example runs as printed (so the README stays true)."""

import pathlib
import re
import runpy

ROOT = pathlib.Path(__file__).resolve().parents[2]


def test_readme_core_example_runs(tmp_path, capsys):
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    assert blocks, "README.md has no python example"
    script = tmp_path / "example.py"
    script.write_text(blocks[0], encoding="utf-8")
    runpy.run_path(str(script), run_name="__main__")
    out = capsys.readouterr().out.splitlines()
    assert out[0] == "(8, 3)"
    assert out[1].startswith("hemicube ")
    # The closed cube's rows sum to 1: the last line prints them.
    assert set(out[-1].strip("[]").split()) == {"1."}
