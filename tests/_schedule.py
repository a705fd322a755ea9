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

# Measured 2026-11-26 at afa4670 (python3 -m pytest --durations=0 in /work/main, 2 workers, this
# idle 2-core machine; pytest 7:56, 1,237 tests; sum 910 s: run to run the same code measured
# 7:55-8:17 and sums of 910-955 s).
SECONDS: dict[str, float] = {
    "test_notebooks.py": 65,
    "test_singular_domain.py": 65,
    "test_ik.py": 41,
    "test_representations.py": 35,
    "test_ik_defaults.py": 31,
    "test_model.py": 30,
    "test_jacobian_properties.py": 29,
    "test_derivatives.py": 29,
    "test_docs_site.py": 27,
    "test_ik_wholebody.py": 27,
    "test_urdf_pinocchio.py": 26,
    "test_eager.py": 26,
    "test_ik_implicit.py": 26,
    "test_calibration.py": 22,
    "test_floating_base.py": 22,
    "test_cli.py": 21,
    "test_multi_frame.py": 20,
    "test_zoo.py": 20,
    "test_scale.py": 19,
    "test_analysis.py": 17,
    "test_error_hints.py": 15,
    "test_motion.py": 13,
    "test_urdf_fuzz.py": 13,
    "test_testing.py": 13,
    "test_doctests.py": 13,
    "test_so3_singular.py": 12,
    "test_writers.py": 12,
    "test_robot_values.py": 11,
    "test_tasks.py": 11,
    "test_nonfinite.py": 11,
    "test_readme.py": 10,
    "test_com.py": 10,
    "test_gimbal_lock.py": 10,
    "test_viz.py": 10,
    "test_viewer.py": 9,
    "test_oracle_pinocchio.py": 8,
    "test_urdf_long_chain.py": 8,
    "test_jacobian_speed_paths.py": 8,
    "test_inverse_velocity.py": 8,
    "test_scan_kernel.py": 7,
    "test_oracle_rtb.py": 7,
    "test_kernel_structure.py": 7,
    "test_urdf_dh.py": 7,
    "test_urdf_export.py": 7,
    "test_multihost.py": 7,
    "test_mjcf_models.py": 7,
    "test_urdf_loading.py": 6,
    "test_fusion_structure.py": 6,
    "test_careless_calls.py": 6,
    "test_spatial.py": 6,
    "test_chapter.py": 4,
    "test_compilation.py": 4,
    "test_mjcf.py": 4,
    "test_mjcf_free_ball.py": 4,
    "test_default_frame.py": 3,
    "test_layering.py": 3,
    "test_compile_options.py": 3,
    "test_zero_dof.py": 3,
    "test_public_api.py": 2,
    "test_batch.py": 1,
    "test_cli_hostile.py": 1,
    "test_csv_output.py": 1,
    "test_viewer_paths.py": 1,
    "test_xacro_hostile.py": 1,
    "test_urdf_mujoco.py": 1,
    "test_bench_peers.py": 0,
    "test_urdf_malformed.py": 0,
    "test_robot_files.py": 0,
    "test_joint_placement.py": 0,
    "test_mjcf_files.py": 0,
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
