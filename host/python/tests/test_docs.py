"""docs/python.md runs as written: its ```python blocks are executed in order, in one namespace,
in an empty directory, with the data directory given by GPMM_DATA (as gpmm.data_dir() reads it)."""

import os
import re

import numpy as np

from conftest import ROOT

DOC = ROOT / "docs" / "python.md"


def python_blocks(text):
    """(first line number, code) of every ```python block."""
    blocks = []
    for m in re.finditer(r"^```python\n(.*?)^```", text, re.S | re.M):
        line = text.count("\n", 0, m.start()) + 2
        blocks.append((line, m.group(1)))
    return blocks


def test_the_doc_has_the_tour_blocks():
    blocks = python_blocks(DOC.read_text())
    assert len(blocks) >= 5, "the tour, fitting, blobs, errors, from_arrays, batch and learning blocks"
    assert all("gpmm" in code for _, code in blocks)


def test_the_tour_runs_as_written(tmp_path, monkeypatch, data_dir):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("GPMM_DATA", str(data_dir))
    text = DOC.read_text()
    namespace = {"__name__": "docs_python_md"}
    for line, code in python_blocks(text):
        # Padding keeps tracebacks pointing at the document's own line numbers.
        exec(compile("\n" * (line - 1) + code, str(DOC), "exec"), namespace)
    # What the blocks say they produce.
    assert (tmp_path / "face.gpmm").is_file() and (tmp_path / "face.h5").is_file()
    assert namespace["image"].shape == (256, 256, 4)
    assert namespace["fit"]["shape"].shape == (50,)
    assert namespace["missing"] == "no-such-model.gpmm"
    assert "shape_rank = 500" in namespace["message"]
    assert namespace["mine"].rank_shape == 10 and np.isfinite(namespace["mine_fit"]["log_likelihood"])
    assert [r["name"] for r in namespace["results"]] == ["astronaut.png", "obama.jpg"]
    assert len(namespace["lines"]) == 2
    learned = namespace["learned"]
    assert (tmp_path / learned["model"]).is_file() and learned["iterations"][0]["accepted"] >= 2
    two = [r for r in learned["iterations"][0]["records"] if r["image"].endswith("two_people.jpg")]
    assert len(two) == 1 and not two[0]["accepted"] and "two_people.pts" in two[0]["reason"], two


def test_the_tour_runs_as_a_script(tmp_path, data_dir):
    """The tour's blocks pasted one after another into a file run as a program: nothing in them
    needs the `if __name__ == "__main__":` guard a cluster of worker processes would."""
    import subprocess
    import sys

    script = tmp_path / "tour.py"
    script.write_text("\n".join(code for _, code in python_blocks(DOC.read_text())))
    env = {**os.environ, "GPMM_DATA": str(data_dir)}
    p = subprocess.run([sys.executable, str(script)], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=900)
    assert p.returncode == 0, p.stderr[-3000:]
    assert (tmp_path / "face.gpmm").is_file()
