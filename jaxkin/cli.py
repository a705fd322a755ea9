"""The ``jaxkin`` command line.

``jaxkin velocities [ROBOT] --n N`` samples N configurations and joint velocities of a zoo robot,
computes for each the hand-built geometric Jacobian, the autodiff one (``jax.jacfwd``) as a check,
the analytical Jacobian with its representation margin, the twist ``J @ qd`` and the singular
values of ``J``, in compiled chunks (:func:`jaxkin.batch.chunked_map`); prints a summary and
writes everything to an ``.npz`` file. ``jaxkin robots`` lists the zoo.

Exit codes: 0 success; 1 the hand-built and autodiff Jacobians disagree (FAIL); 2 a usage error
(one line on stderr starting ``jaxkin: error:``); 130 interrupted.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import sys
import tempfile
from collections.abc import Iterator, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

import jaxkin as jk

from .batch import ProgressBar, chunked_map
from .jacobians import REFERENCES
from .representations import REPRESENTATIONS

__all__ = ["main", "sample_configurations", "velocity_kernel"]

PROGRESS_MIN_N = 200_000
# Rows per compiled call. Smaller than chunked_map's default: this kernel (three Jacobians and an
# SVD per row) has many intermediates, and on a 2-core CPU 4096 rows ran 1.5 - 2x faster than
# 65536 (their working set stays in cache).
CLI_CHUNK_SIZE = 4096
CHECK_TOL = {"float64": 1e-10, "float32": 1e-4}
# Half-width of the sampling interval on an unbounded side: radians (revolute), metres (prismatic).
UNBOUNDED_HALF_WIDTH = {"revolute": math.pi, "prismatic": 1.0}


class UsageError(Exception):
    """A mistake in the command line or its values: reported in one line, exit code 2."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # argparse prints usage and exits; we report one line
        raise UsageError(f"{message} (see '{self.prog} --help')")


# ---------------------------------------------------------------------- argument types
def _positive_int(text: str) -> int:
    """A positive integer; ``1_000_000`` and ``1e6`` are accepted."""
    try:
        value = int(text)
    except ValueError:
        try:
            number = float(text)
        except ValueError:
            number = math.nan
        if not (math.isfinite(number) and number.is_integer()):
            raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
        value = int(number)
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {value}")
    return value


def _seed(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer >= 0, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected an integer >= 0, got {value}")
    return value


def _finite(text: str, *, positive: bool) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value) or value < 0 or (positive and value == 0):
        want = "a finite number > 0" if positive else "a finite number >= 0"
        raise argparse.ArgumentTypeError(f"expected {want}, got {text!r}")
    return value


def _nonnegative_float(text: str) -> float:
    return _finite(text, positive=False)


def _positive_float(text: str) -> float:
    return _finite(text, positive=True)


def _frame(text: str) -> int | str:
    try:
        return int(text)
    except ValueError:
        return text


# ---------------------------------------------------------------------- parser
_VELOCITIES_EPILOG = f"""\
sampling:
  q is uniform within each joint's limits; an unbounded side is taken as -pi/pi rad for a
  revolute joint and -1/1 m for a prismatic one (or the finite side -/+ 2 pi rad, 2 m when that
  would leave an empty interval). qd is uniform in [-s, s] rad/s (revolute) or m/s (prismatic),
  s = --qd-scale. Both come from numpy's default_rng(--seed).

near-singularity criteria (tol = --singular-tol):
  kinematic:       sigma_min / sigma_max < tol, the singular values of the 6 x dof geometric
                   Jacobian J (min(6, dof) of them), i.e. J is numerically rank deficient. J mixes
                   m/rad and rad/rad rows, so the ratio depends on the unit of length; a frame
                   moved by fewer than min(6, dof) joints counts as singular everywhere.
  representation:  margin < tol, where margin is the distance of the frame's orientation from the
                   representation's singularity: |cos(pitch)| for rpy, |sin(theta)| for zyz,
                   1 - |w| / (2 pi) for rotvec. The analytical Jacobian grows like 1 / margin.

check:
  max |J_handbuilt - J_jacfwd| over all entries and configurations must be at most
  {CHECK_TOL["float64"]:g} (float64) or {CHECK_TOL["float32"]:g} (float32); otherwise FAIL, exit 1.

output (.npz, written to a temporary file in the same directory, then renamed):
  q (N, dof), qd (N, dof), twist (N, 6) = J @ qd, J (N, 6, dof) geometric at --reference,
  Ja (N, 6, dof) analytical d[p; phi]/dq, margin (N,), sigma (N, min(6, dof)); metadata robot,
  joint_names, frame, reference, representation, dtype, seed, qd_scale, singular_tol,
  jaxkin_version. Rows of J and twist are [v; omega].
"""


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="jaxkin",
        description="Differential kinematics of robot manipulators in JAX.",
    )
    parser.add_argument("--version", action="version", version=f"jaxkin {jk.__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    robots = sub.add_parser("robots", help="list the robot zoo", description="List the zoo.")
    robots.set_defaults(handler=cmd_robots)

    vel = sub.add_parser(
        "velocities",
        help="batched Jacobians and end-effector twists of sampled configurations",
        description=(
            "Sample N configurations and joint velocities of a zoo robot; compute the geometric\n"
            "Jacobian (hand-built, checked against jax.jacfwd), the analytical Jacobian, the\n"
            "twist J @ qd and the singular values of J; print a summary and write an .npz."
        ),
        epilog=_VELOCITIES_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    vel.set_defaults(handler=cmd_velocities)
    vel.add_argument(
        "robot",
        nargs="?",
        default="niryo_one",
        metavar="ROBOT",
        help="zoo robot name (default: %(default)s; see 'jaxkin robots')",
    )
    vel.add_argument(
        "--n", type=_positive_int, default=100_000, help="configurations (default: %(default)s)"
    )
    vel.add_argument("--seed", type=_seed, default=0, help="random seed (default: %(default)s)")
    vel.add_argument(
        "--chunk-size",
        type=_positive_int,
        default=CLI_CHUNK_SIZE,
        help="configurations per compiled call (default: %(default)s)",
    )
    vel.add_argument(
        "--dtype",
        choices=("float32", "float64"),
        default="float64",
        help="float precision (default: %(default)s; float64 enables jax_enable_x64 for this run)",
    )
    out = vel.add_mutually_exclusive_group()
    out.add_argument(
        "--output",
        metavar="PATH",
        help="output file (default: velocities_<robot>_<n>.npz in the current directory)",
    )
    out.add_argument("--no-output", action="store_true", help="compute and summarise only")
    vel.add_argument(
        "--frame",
        type=_frame,
        default=None,
        help="frame name or index (default: the tip, tool included)",
    )
    vel.add_argument(
        "--reference",
        choices=REFERENCES,
        default="world_aligned",
        help="point and basis of J and the twist (default: %(default)s: frame origin, world axes)",
    )
    vel.add_argument(
        "--representation",
        choices=REPRESENTATIONS,
        default="rpy",
        help="orientation representation of the analytical Jacobian (default: %(default)s)",
    )
    vel.add_argument(
        "--qd-scale",
        type=_nonnegative_float,
        default=1.0,
        metavar="S",
        help="joint velocities uniform in [-S, S] rad/s or m/s (default: %(default)s)",
    )
    vel.add_argument(
        "--singular-tol",
        type=_positive_float,
        default=1e-3,
        metavar="TOL",
        help="near-singularity threshold, see below (default: %(default)s)",
    )
    vel.add_argument(
        "--progress",
        action=argparse.BooleanOptionalAction,
        default=None,
        help=f"progress bar on stderr (default: on for N >= {PROGRESS_MIN_N:,} on a terminal)",
    )
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line with ``argv`` (default: ``sys.argv[1:]``); returns the exit code."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except UsageError as e:
        return _usage_error(str(e))
    except SystemExit as e:  # --help, --version
        return e.code if isinstance(e.code, int) else 0
    if args.command is None:
        return _usage_error("choose a command: velocities or robots (see 'jaxkin --help')")
    try:
        return args.handler(args)
    except (UsageError, jk.JaxkinError) as e:
        return _usage_error(str(e))
    except KeyboardInterrupt:
        print("jaxkin: interrupted", file=sys.stderr)
        return 130


def _usage_error(message: str) -> int:
    line = " ".join(message.split())
    print(f"jaxkin: error: {line}", file=sys.stderr)
    return 2


# ---------------------------------------------------------------------- robots
def cmd_robots(args: argparse.Namespace) -> int:
    names = jk.robots.names()
    width = max(len(n) for n in names)
    for name in names:
        print(f"{name:<{width}}  {jk.robots.info(name).description}")
    return 0


# ---------------------------------------------------------------------- velocities
def sample_configurations(
    robot: jk.Robot, n: int, seed: int, qd_scale: float, dtype: Any
) -> tuple[np.ndarray, np.ndarray]:
    """Joint values uniform within the limits and joint velocities uniform in
    ``[-qd_scale, qd_scale]``; both of shape (n, dof) and ``dtype``.

    An unbounded side of a joint's range is taken as -/+ pi (revolute) or -/+ 1 m (prismatic), or
    as the finite side -/+ 2 pi (2 m) when the former would leave an empty interval.
    """
    lo = np.asarray(robot.lower, dtype=np.float64).copy()
    hi = np.asarray(robot.upper, dtype=np.float64).copy()
    for i, kind in enumerate(robot.joint_kinds):
        w = UNBOUNDED_HALF_WIDTH[kind]
        if not np.isfinite(lo[i]):
            lo[i] = -w if (not np.isfinite(hi[i]) or hi[i] > -w) else hi[i] - 2 * w
        if not np.isfinite(hi[i]):
            hi[i] = w if lo[i] < w else lo[i] + 2 * w
    rng = np.random.default_rng(seed)
    q = (lo + (hi - lo) * rng.random((n, robot.dof))).astype(dtype)
    qd = rng.uniform(-qd_scale, qd_scale, (n, robot.dof)).astype(dtype)
    return q, qd


def velocity_kernel(robot: jk.Robot, frame: int | str | None, reference: str, representation: str):
    """The per-configuration function ``f(q, qd) -> dict`` that ``velocities`` maps.

    Output shapes for one configuration: ``J`` (6, dof) hand-built geometric Jacobian at
    ``reference``; ``Ja`` (6, dof) analytical Jacobian ``d[p; phi]/dq``; ``margin`` () its
    representation margin; ``twist`` (6,) ``= J @ qd``, ``[v; omega]``; ``sigma`` (min(6, dof),)
    singular values of ``J``, descending; ``jac_err`` () ``max |J - jacobian_fwd|``.
    """

    def per_config(q, qd):
        J = jk.geometric_jacobian(robot, q, frame=frame, reference=reference)
        J_ad = jk.jacobian_fwd(robot, q, frame=frame, reference=reference)
        Ja, margin = jk.analytical_jacobian(
            robot, q, representation, frame=frame, return_margin=True
        )
        return {
            "J": J,
            "Ja": Ja,
            "margin": margin,
            "twist": J @ qd,
            "sigma": jnp.linalg.svd(J, compute_uv=False),
            "jac_err": jnp.max(jnp.abs(J - J_ad)),
        }

    return per_config


@contextlib.contextmanager
def _x64(enabled: bool) -> Iterator[None]:
    """Turn ``jax_enable_x64`` on for this command when float64 is asked; restore it after."""
    before = jax.config.read("jax_enable_x64")
    if enabled and not before:
        jax.config.update("jax_enable_x64", True)
    try:
        yield
    finally:
        if jax.config.read("jax_enable_x64") != before:
            jax.config.update("jax_enable_x64", before)


class AtomicOutput:
    """An output file that appears complete or not at all.

    Opening creates a temporary file next to ``path`` (so a bad path fails before any work);
    :meth:`commit` writes the arrays there and renames it onto ``path`` (``os.replace``). Leaving
    the ``with`` block without a commit (an exception, Ctrl-C) removes the temporary file.
    """

    def __init__(self, path: str) -> None:
        self.path = os.path.abspath(path)
        self.tmp: str | None = None

    def __enter__(self) -> AtomicOutput:
        directory, name = os.path.split(self.path)
        if os.path.isdir(self.path):
            raise UsageError(f"output path {self.path} is a directory; give a file name")
        if not os.path.isdir(directory):
            raise UsageError(
                f"cannot write {self.path}: directory {directory} does not exist; create it "
                "or choose another --output"
            )
        try:
            fd, self.tmp = tempfile.mkstemp(prefix=f".{name}.", suffix=".tmp", dir=directory)
        except OSError as e:
            raise UsageError(
                f"cannot write {self.path}: {e.strerror or e}; choose another --output"
            ) from None
        os.close(fd)
        return self

    def commit(self, arrays: dict[str, np.ndarray]) -> None:
        if self.tmp is None:
            raise RuntimeError("AtomicOutput.commit must be called once, inside its 'with' block")
        try:
            with open(self.tmp, "wb") as f:
                np.savez(f, **arrays)
                f.flush()
                os.fsync(f.fileno())
            umask = os.umask(0)
            os.umask(umask)
            os.chmod(self.tmp, 0o666 & ~umask)
            os.replace(self.tmp, self.path)
        except OSError as e:
            raise UsageError(f"cannot write {self.path}: {e.strerror or e}") from None
        self.tmp = None

    def __exit__(self, *exc: Any) -> None:
        if self.tmp is not None:
            with contextlib.suppress(OSError):
                os.remove(self.tmp)
            self.tmp = None


def cmd_velocities(args: argparse.Namespace) -> int:
    if args.robot not in jk.robots.names():
        raise UsageError(
            f"unknown robot {args.robot!r}; choose one of {', '.join(jk.robots.names())} "
            "(see 'jaxkin robots')"
        )
    with _x64(args.dtype == "float64"):
        robot = jk.robots.load(args.robot, dtype=args.dtype)
        frame_name = robot.frame_names[robot.frame_index(args.frame)]
        if args.no_output:
            return _velocities(args, robot, frame_name, None)
        path = args.output or f"velocities_{args.robot}_{args.n}.npz"
        with AtomicOutput(path) as output:
            return _velocities(args, robot, frame_name, output)


def _velocities(
    args: argparse.Namespace, robot: jk.Robot, frame_name: str, output: AtomicOutput | None
) -> int:
    dtype = np.dtype(args.dtype)
    q, qd = sample_configurations(robot, args.n, args.seed, args.qd_scale, dtype)
    fn = velocity_kernel(robot, frame_name, args.reference, args.representation)
    if args.progress is None:
        show = args.n >= PROGRESS_MIN_N
        bar = ProgressBar(args.n, "velocities", unit="cfg", enabled=show)
    else:
        bar = ProgressBar(args.n, "velocities", unit="cfg", enabled=args.progress, force=True)
    res, stats = chunked_map(fn, q, qd, chunk_size=args.chunk_size, progress=bar, return_stats=True)

    tol = args.singular_tol
    sigma = res["sigma"]
    kin_singular = int(np.count_nonzero(~(sigma[:, -1] > tol * sigma[:, 0])))
    rep_singular = int(np.count_nonzero(~(res["margin"] >= tol)))
    jac_err = float(np.max(res["jac_err"]))
    check_tol = CHECK_TOL[args.dtype]
    passed = jac_err <= check_tol  # False for NaN

    if output is not None:
        arrays = {
            "q": q,
            "qd": qd,
            "twist": res["twist"],
            "J": res["J"],
            "Ja": res["Ja"],
            "margin": res["margin"],
            "sigma": sigma,
            "robot": np.array(robot.name),
            "joint_names": np.array(robot.joint_names),
            "frame": np.array(frame_name),
            "reference": np.array(args.reference),
            "representation": np.array(args.representation),
            "dtype": np.array(args.dtype),
            "seed": np.array(args.seed),
            "qd_scale": np.array(args.qd_scale),
            "singular_tol": np.array(tol),
            "jaxkin_version": np.array(jk.__version__),
        }
        output.commit(arrays)

    n = args.n
    pct = lambda k: 100.0 * k / n  # noqa: E731
    margin_name = {"rpy": "|cos(pitch)|", "zyz": "|sin(theta)|", "rotvec": "1 - |w|/(2 pi)"}
    lines = [
        f"robot            {robot.name} ({robot.dof} dof: {', '.join(robot.joint_names)})",
        f"frame            {frame_name}, reference {args.reference}, "
        f"representation {args.representation}",
        f"configurations   {n:,} (seed {args.seed}, qd uniform in [-{args.qd_scale:g}, "
        f"{args.qd_scale:g}] rad/s or m/s)",
        f"dtype            {args.dtype}",
        f"chunks           {stats.n_chunks} x {stats.chunk_size:,} "
        f"({stats.padding:,} padding rows)",
        f"compile          {stats.compile_seconds:.2f} s (once, for the chunk shape)",
        f"throughput       {stats.rate:,.0f} configurations/s "
        f"({stats.run_seconds:.2f} s, compile excluded)",
        f"check            max |J_handbuilt - J_jacfwd| = {jac_err:.3g}  "
        f"{'PASS' if passed else 'FAIL'} (tol {check_tol:g})",
        f"near kinematic singularity       {kin_singular:,} ({pct(kin_singular):.3g}%): "
        f"sigma_min/sigma_max < {tol:g}",
        f"near representation singularity  {rep_singular:,} ({pct(rep_singular):.3g}%): "
        f"{margin_name[args.representation]} < {tol:g}",
        _norm_line("|v|     [m/s]", res["twist"][:, :3]),
        _norm_line("|omega| [rad/s]", res["twist"][:, 3:]),
    ]
    if output is not None:
        size = os.path.getsize(output.path)
        lines.append(f"output           {output.path} ({size / 1e6:,.1f} MB)")
    else:
        lines.append("output           none (--no-output)")
    print("jaxkin velocities")
    for line in lines:
        print(f"  {line}")
    if not passed:
        print(
            "jaxkin: the hand-built and autodiff Jacobians disagree beyond tolerance",
            file=sys.stderr,
        )
        return 1
    return 0


def _norm_line(label: str, vectors: np.ndarray) -> str:
    norms = np.linalg.norm(vectors.astype(np.float64, copy=False), axis=1)
    lo, med, p99, hi = np.percentile(norms, [0, 50, 99, 100])
    return (
        f"{label:<16} min {lo:.4g}  mean {norms.mean():.4g}  median {med:.4g}  "
        f"p99 {p99:.4g}  max {hi:.4g}"
    )
