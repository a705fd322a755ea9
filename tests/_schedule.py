"""Order in which the test files are handed to pytest-xdist's workers: heaviest first.

``--dist loadfile`` sends whole files to the two workers in collection order (addopts pass
``--no-loadscope-reorder``; xdist would otherwise sort files by their number of tests, and a
file of a few slow compiles then comes last and runs alone while the other worker idles).
Starting with the heaviest files leaves light ones for the end, where they even out the two
workers. ``SECONDS`` holds each file's measured time (setup, call and teardown of its tests,
one worker); a file missing from it counts as :data:`UNKNOWN`.

Regenerate after the suite changes (about 18 minutes)::

    python3 -m pytest --durations=0 -q > /tmp/durations.txt
    python3 tests/_schedule.py /tmp/durations.txt    # prints SECONDS to paste here
"""

from __future__ import annotations

import re
import sys
from collections import defaultdict

UNKNOWN = 20.0

# Measured 2026-11-24 (python3 -m pytest --durations=0, 2 workers, this 2-core machine).
SECONDS: dict[str, float] = {
    "test_representations.py": 146,
    "test_notebooks.py": 131,
    "test_ik_implicit.py": 124,
    "test_model.py": 115,
    "test_ik.py": 107,
    "test_jacobian_properties.py": 105,
    "test_singular_domain.py": 98,
    "test_ik_defaults.py": 84,
    "test_cli.py": 76,
    "test_eager.py": 75,
    "test_scale.py": 71,
    "test_urdf_fuzz.py": 66,
    "test_calibration.py": 62,
    "test_error_hints.py": 54,
    "test_floating_base.py": 51,
    "test_spatial.py": 48,
    "test_analysis.py": 47,
    "test_derivatives.py": 47,
    "test_testing.py": 37,
    "test_zoo.py": 36,
    "test_robot_values.py": 32,
    "test_urdf_pinocchio.py": 31,
    "test_urdf_mujoco.py": 30,
    "test_readme.py": 25,
    "test_docs_site.py": 25,
    "test_inverse_velocity.py": 24,
    "test_urdf_export.py": 22,
    "test_chapter.py": 20,
    "test_gimbal_lock.py": 17,
    "test_viewer.py": 15,
    "test_kernel_structure.py": 14,
    "test_nonfinite.py": 13,
    "test_mjcf_models.py": 13,
    "test_oracle_rtb.py": 13,
    "test_viz.py": 13,
    "test_oracle_pinocchio.py": 12,
    "test_urdf_dh.py": 11,
    "test_urdf_long_chain.py": 11,
    "test_doctests.py": 11,
    "test_urdf_loading.py": 10,
    "test_writers.py": 8,
    "test_mjcf.py": 6,
    "test_default_frame.py": 6,
    "test_multihost.py": 6,
    "test_mjcf_free_ball.py": 5,
    "test_compilation.py": 5,
    "test_batch.py": 4,
    "test_zero_dof.py": 3,
    "test_urdf_malformed.py": 0,
    "test_joint_placement.py": 0,
    "test_xacro.py": 0,
}


def weight(path: str) -> float:
    """Seconds of the test file at ``path`` (a path ending in ``tests/<name>.py``)."""
    return SECONDS.get(path.replace("\\", "/").rsplit("/", 1)[-1], UNKNOWN)


def parse(report: str) -> dict[str, float]:
    """Per-file totals from pytest's ``--durations=0`` report, largest first."""
    totals: dict[str, float] = defaultdict(float)
    for m in re.finditer(r"^([\d.]+)s (?:setup|call|teardown)\s+tests/([^:\s]+\.py)", report, re.M):
        totals[m.group(2)] += float(m.group(1))
    return dict(sorted(totals.items(), key=lambda kv: -kv[1]))


if __name__ == "__main__":
    text = open(sys.argv[1]).read()
    print("SECONDS: dict[str, float] = {")
    for name, s in parse(text).items():
        print(f'    "{name}": {s:.0f},')
    print("}")
