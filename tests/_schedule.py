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

# Measured 2026-11-26 at b1a0b8c (python3 -m pytest --durations=0 in /work/main, 2 workers, this
# idle 2-core machine; pytest 8:11, 1,227 tests; sum 926 s).
SECONDS: dict[str, float] = {
    "test_singular_domain.py": 67,
    "test_notebooks.py": 64,
    "test_representations.py": 41,
    "test_ik.py": 37,
    "test_jacobian_properties.py": 36,
    "test_ik_implicit.py": 30,
    "test_urdf_pinocchio.py": 30,
    "test_docs_site.py": 29,
    "test_zoo.py": 28,
    "test_derivatives.py": 28,
    "test_ik_wholebody.py": 27,
    "test_ik_defaults.py": 26,
    "test_calibration.py": 25,
    "test_model.py": 25,
    "test_scale.py": 24,
    "test_analysis.py": 22,
    "test_cli.py": 22,
    "test_eager.py": 22,
    "test_floating_base.py": 21,
    "test_multi_frame.py": 16,
    "test_doctests.py": 14,
    "test_com.py": 13,
    "test_motion.py": 12,
    "test_error_hints.py": 12,
    "test_robot_values.py": 11,
    "test_viewer.py": 11,
    "test_urdf_fuzz.py": 11,
    "test_nonfinite.py": 11,
    "test_writers.py": 10,
    "test_tasks.py": 10,
    "test_readme.py": 10,
    "test_testing.py": 10,
    "test_gimbal_lock.py": 10,
    "test_urdf_long_chain.py": 9,
    "test_scan_kernel.py": 9,
    "test_so3_singular.py": 9,
    "test_viz.py": 9,
    "test_urdf_export.py": 9,
    "test_kernel_structure.py": 8,
    "test_urdf_dh.py": 8,
    "test_jacobian_speed_paths.py": 8,
    "test_inverse_velocity.py": 8,
    "test_oracle_pinocchio.py": 8,
    "test_spatial.py": 7,
    "test_mjcf_models.py": 7,
    "test_fusion_structure.py": 7,
    "test_oracle_rtb.py": 7,
    "test_urdf_loading.py": 7,
    "test_chapter.py": 6,
    "test_multihost.py": 6,
    "test_careless_calls.py": 5,
    "test_mjcf.py": 3,
    "test_default_frame.py": 3,
    "test_compilation.py": 3,
    "test_mjcf_free_ball.py": 3,
    "test_compile_options.py": 3,
    "test_zero_dof.py": 2,
    "test_public_api.py": 1,
    "test_layering.py": 1,
    "test_batch.py": 1,
    "test_cli_hostile.py": 1,
    "test_csv_output.py": 1,
    "test_xacro_hostile.py": 1,
    "test_viewer_paths.py": 1,
    "test_urdf_mujoco.py": 0,
    "test_bench_peers.py": 0,
    "test_robot_files.py": 0,
    "test_joint_placement.py": 0,
    "test_urdf_malformed.py": 0,
    "test_mjcf_files.py": 0,
    "test_xacro.py": 0,
    "test_suite_helpers.py": 0,
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
