"""README.md's Python code blocks run as written, in order, in one namespace.

They run in a fresh interpreter with JAX's defaults (float32, as a reader who pastes them has;
no test-suite configuration), from a temporary working directory. A block that is not meant to
run starts with a line ``# not run: <reason>``; the number of such blocks is pinned below, so
that a block cannot silently stop being checked. The interpreter inherits the suite's
``XLA_FLAGS`` (LLVM's optimisation off, tests/conftest.py: compiling is most of this test's
time).
"""

from __future__ import annotations

import json
import pathlib
import re
import subprocess
import sys
import textwrap

import pytest

README = pathlib.Path(__file__).parent.parent / "README.md"
SKIP_MARK = "# not run:"
# Blocks marked "# not run: ..." today. Change only together with the README.
EXPECTED_SKIPPED = 0
# At least the "API at a glance" and "Batches, chunks and devices" blocks.
MIN_RUN = 2

_FENCE = re.compile(r"^```python[ \t]*\n(.*?)^```[ \t]*$", re.MULTILINE | re.DOTALL)


def python_blocks(text: str) -> list[tuple[int, str]]:
    """``(first line number, code)`` of each ```python block of ``text``, in order."""
    return [(text.count("\n", 0, m.start(1)) + 1, m.group(1)) for m in _FENCE.finditer(text)]


# Runs in the subprocess: each block in turn in one namespace; on failure, the block's README
# line and the traceback; at the end, a few shapes the README's comments promise.
_RUNNER = textwrap.dedent(
    """
    import json, sys, traceback
    blocks = json.loads(sys.stdin.read())
    ns = {"__name__": "__readme__"}
    for line, code in blocks:
        try:
            exec(compile(code, f"README.md:{line}", "exec"), ns)
        except BaseException:
            print(f"README block at line {line} failed:", file=sys.stderr)
            traceback.print_exc()
            sys.exit(1)
    import numpy as np
    shapes = {}
    for name in ("q", "T", "J", "Ja", "V", "qs", "Js", "Jd", "H", "m", "T_targets"):
        if name in ns:
            shapes[name] = list(np.shape(ns[name]))
    if "sol" in ns:
        shapes["sol.q"] = list(np.shape(ns["sol"].q))
        shapes["sol.converged"] = list(np.shape(ns["sol"].converged))
    if "out" in ns:
        shapes["out"] = {k: list(np.shape(v)) for k, v in ns["out"].items()}
    if "path" in ns:
        with np.load(ns["path"]) as f:
            shapes["file"] = {k: list(f[k].shape) for k in f.files}
    if "part" in ns:
        shapes["part"] = {k: list(np.shape(v)) for k, v in ns["part"].items()}
    print("SHAPES " + json.dumps(shapes))
    """
)


def test_readme_has_the_expected_blocks():
    blocks = python_blocks(README.read_text())
    skipped = [line for line, code in blocks if code.lstrip().startswith(SKIP_MARK)]
    assert len(skipped) == EXPECTED_SKIPPED, (
        f"README blocks marked {SKIP_MARK!r} at lines {skipped}; expected {EXPECTED_SKIPPED}"
    )
    assert len(blocks) - len(skipped) >= MIN_RUN


@pytest.mark.slow  # eager calls and four compiles: about a minute on a busy 2-core CPU
def test_readme_python_blocks_run(tmp_path):
    blocks = [
        (line, code)
        for line, code in python_blocks(README.read_text())
        if not code.lstrip().startswith(SKIP_MARK)
    ]
    proc = subprocess.run(
        [sys.executable, "-c", _RUNNER],
        input=json.dumps(blocks),
        capture_output=True,
        text=True,
        cwd=tmp_path,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr[-6000:]
    assert list(tmp_path.iterdir()) == [], "README blocks should write only to temporary paths"
    shapes = json.loads(proc.stdout.rsplit("SHAPES ", 1)[1])

    # The shapes the README's comments state (puma560: dof 6; qs: 1000; 8 IK targets).
    dof, n = 6, 1000
    assert shapes["T"] == [4, 4]
    assert shapes["J"] == shapes["Ja"] == shapes["Jd"] == [6, dof]
    assert shapes["V"] == [6]
    assert shapes["H"] == [dof, 6, dof]
    assert shapes["m"] == []
    assert shapes["qs"] == [n, dof]
    assert shapes["Js"] == [n, 6, dof]
    assert shapes["T_targets"] == [8, 4, 4]
    assert shapes["sol.q"] == [8, dof]
    assert shapes["sol.converged"] == [8]
    assert shapes["out"] == {"J": [n, 6, dof], "V": [n, 6]}
    assert shapes["file"] == {"J": [n, 6, dof], "V": [n, 6]}
    assert shapes["part"] == {"J": [n, 6, dof], "V": [n, 6]}
