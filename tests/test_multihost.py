"""chunked_map over a multi-process device set: two JAX processes on localhost, exact results.

Two child processes call ``jax.distributed.initialize`` (coordinator on a free localhost port,
CPU devices, JAX's default CPU collectives: gloo over TCP) and evaluate the same
``jaxkin.batch.chunked_map`` over the global device set (2 processes x 2 CPU devices). Each
returns the whole result on its host. The test process computes the same map on its own
devices alone and requires every child's result to be bitwise identical to it, and to a
plain ``jit(vmap)`` of the kernel as an independent check of the map itself.

Every process here compiles with XLA's defaults (the suite's ``XLA_FLAGS`` removed: at LLVM's
``-O0`` the last bit can depend on the batch shape, and bitwise equality across chunkings is a
property of the programs users compile), so the reference runs in a third process.
"""

import json
import os
import socket
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import jaxkin as jk

N_ROWS = 37  # not a multiple of the chunk (8 rows) nor of the 4 devices: the last chunk is padded
CHUNK = 8
SEED = 7
ROBOT = "scara"  # 4 joints, revolute and prismatic: compiles in well under a second
TIMEOUT_S = 90

# The child's program: the same robot, inputs and map as the reference in the test below.
CHILD = textwrap.dedent(
    """
    import json, sys
    import jax
    jax.config.update("jax_enable_x64", True)
    jax.config.update("jax_num_cpu_devices", 2)
    jax.config.update("jax_cpu_collectives_implementation", "gloo")
    address, pid, out = sys.argv[1], int(sys.argv[2]), sys.argv[3]
    jax.distributed.initialize(
        coordinator_address=address, num_processes=2, process_id=pid, initialization_timeout=60
    )
    import numpy as np
    import jaxkin as jk
    from jaxkin.batch import chunked_map
    from tests.test_multihost import CHUNK, ROBOT, inputs, kernel

    robot = jk.robots.load(ROBOT)
    q = inputs(robot)
    J, T = chunked_map(kernel(robot), q, chunk_size=CHUNK)
    np.savez(out, J=J, T=T)
    json.dump(
        {"process_count": jax.process_count(), "devices": len(jax.devices()),
         "local": len(jax.local_devices())},
        open(out + ".json", "w"),
    )
    jax.distributed.shutdown()
    """
)


# The reference: the same map on one process's devices, and a plain jit(vmap) of the kernel.
REFERENCE = textwrap.dedent(
    """
    import sys
    import jax
    jax.config.update("jax_enable_x64", True)
    import numpy as np
    import jaxkin as jk
    from jaxkin import _jit
    from jaxkin.batch import chunked_map
    from tests.test_multihost import CHUNK, ROBOT, inputs, kernel

    robot = jk.robots.load(ROBOT)
    q = inputs(robot)
    J, T = chunked_map(kernel(robot), q, chunk_size=CHUNK)
    options = _jit.compiler_options() or None  # chunked_map's: the same program, the same bits
    J_direct, T_direct = jax.jit(jax.vmap(kernel(robot)), compiler_options=options)(q)
    np.savez(sys.argv[1], J=J, T=T, J_direct=J_direct, T_direct=T_direct)
    """
)


def kernel(robot):
    def f(q):
        return jk.geometric_jacobian(robot, q), jk.fk(robot, q)

    return f


def inputs(robot):
    """Configurations uniform within the limits, unbounded ones cut to +-3 (NumPy: nothing to
    compile)."""
    lower = np.clip(np.asarray(robot.lower), -3.0, 3.0)
    upper = np.clip(np.asarray(robot.upper), -3.0, 3.0)
    return np.random.default_rng(SEED).uniform(lower, upper, (N_ROWS, robot.dof))


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _spawn(*args: str) -> subprocess.Popen:
    env = dict(os.environ)
    env["PYTHONPATH"] = ROOT + os.pathsep + env.get("PYTHONPATH", "")
    env.pop("XLA_FLAGS", None)  # XLA's defaults (see above); the child sets its device count
    env["JAX_PLATFORMS"] = "cpu"
    return subprocess.Popen(
        [sys.executable, "-c", *args],
        cwd=ROOT,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )


def _start_children(tmp_path):
    address = f"127.0.0.1:{_free_port()}"
    outs = [str(tmp_path / f"proc{i}.npz") for i in range(2)]
    procs = [_spawn(CHILD, address, str(i), outs[i]) for i in range(2)]
    return procs, outs


def _wait(procs):
    logs = []
    try:
        for p in procs:
            logs.append(p.communicate(timeout=TIMEOUT_S)[0])
    finally:
        for p in procs:  # a child stuck waiting for its peer must not outlive the test
            if p.poll() is None:
                p.kill()
                p.communicate()
    return logs


def _lacks_cpu_collectives(log: str) -> bool:
    markers = ("gloo", "collectives")
    return any(m in log.lower() for m in markers) and (
        "not supported" in log.lower() or "unimplemented" in log.lower()
    )


def test_chunked_map_two_processes_equals_single_process(tmp_path):
    procs, outs = _start_children(tmp_path)
    ref_out = str(tmp_path / "reference.npz")
    try:  # the single-process reference, computed while the children run
        reference = _spawn(REFERENCE, ref_out)
    finally:
        logs = _wait([*procs, reference])
    assert reference.returncode == 0, f"reference failed:\n{logs[-1][-3000:]}"
    robot = jk.robots.load(ROBOT)
    ref = np.load(ref_out)
    J_ref, T_ref, J_direct, T_direct = ref["J"], ref["T"], ref["J_direct"], ref["T_direct"]
    np.testing.assert_array_equal(J_ref, np.asarray(J_direct))
    np.testing.assert_array_equal(T_ref, np.asarray(T_direct))

    for p, log in zip(procs, logs[:2], strict=True):
        if p.returncode != 0 and _lacks_cpu_collectives(log):
            pytest.skip(f"this jaxlib has no CPU cross-process collectives: {log[-400:]}")
        assert p.returncode == 0, f"child failed (rc {p.returncode}):\n{log[-3000:]}"
    for out in outs:
        with open(out + ".json") as fh:
            info = json.load(fh)
        # really one computation over both processes' devices
        assert info == {"process_count": 2, "devices": 4, "local": 2}
        got = np.load(out)
        assert got["J"].shape == (N_ROWS, 6, robot.dof)
        assert got["J"].dtype == np.float64
        assert np.isfinite(got["J"]).all()
        np.testing.assert_array_equal(got["J"], J_ref)  # bitwise (finite values: equal bits)
        np.testing.assert_array_equal(got["T"], T_ref)
