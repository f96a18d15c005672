"""Every `python` block of README.md and docs/python.md runs as written (the blocks of one file in
order, in one namespace), in a folder holding `gt.h5` made by btf-synth (a small twill). Run by
ctest `python` with the module's other tests."""
import os
import re
import subprocess

import pytest

TOOLS = os.environ.get("BTF_TOOLS_DIR", "")
SOURCE = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))


def python_blocks(path):
    with open(path, encoding="utf-8") as f:
        return re.findall(r"^```python\n(.*?)^```", f.read(), flags=re.S | re.M)


@pytest.mark.parametrize("doc", ["README.md", "docs/python.md"])
def test_every_python_block_runs_as_written(doc, tmp_path, monkeypatch):
    blocks = python_blocks(os.path.join(SOURCE, doc))
    assert blocks, f"{doc} has no python block"
    subprocess.run([os.path.join(TOOLS, "btf-synth"), "btf", "--preset", "twill", "--directions", "bonn81",
                    "--views", "0,1,7", "--lights", "0,3,9,20", "--resolution", "8", "--samples", "1", "-q",
                    "-o", str(tmp_path / "gt.h5")], check=True)
    monkeypatch.chdir(tmp_path)
    namespace = {}
    for i, block in enumerate(blocks):
        exec(compile(block, f"{doc} python block {i + 1}", "exec"), namespace)
