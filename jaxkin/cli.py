"""The ``jaxkin`` command line.

* ``jaxkin robots`` lists the zoo and the example-robot-data URDFs that load by name.
* ``jaxkin jacobian ROBOT --q ...`` prints the geometric (or analytical) Jacobian of one
  configuration as a labelled table, stating its frame, reference and row order.
* ``jaxkin velocities [ROBOT] --n N`` samples N configurations and joint velocities (or reads them
  from a CSV/NPZ file with ``--configurations``) and computes for each the hand-built geometric
  Jacobian, the autodiff one (``jax.jacfwd``) as a check, the analytical Jacobian with its
  representation margin, the twist ``J @ qd`` and the singular values of ``J``, in compiled chunks
  (:func:`jaxkin.batch.chunked_map`); prints a summary and writes an ``.npz`` or ``.csv`` file.

ROBOT is a zoo name (``jaxkin robots``), an example-robot-data name (``erd/panda``) or the path of
a URDF file.

Exit codes: 0 success; 1 the hand-built and autodiff Jacobians disagree (FAIL); 2 a usage error
(one line on stderr starting ``jaxkin: error:``); 130 interrupted.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import pathlib
import re
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

__all__ = [
    "format_jacobian",
    "load_robot",
    "main",
    "read_configurations",
    "sample_configurations",
    "velocity_kernel",
]

PROGRESS_MIN_N = 200_000
# Rows per compiled call. Smaller than chunked_map's default: this kernel (three Jacobians and an
# SVD per row) has many intermediates, and on a 2-core CPU 4096 rows ran 1.5 - 2x faster than
# 65536 (their working set stays in cache).
CLI_CHUNK_SIZE = 4096
CHECK_TOL = {"float64": 1e-10, "float32": 1e-4}
# Half-width of the sampling interval on an unbounded side: radians (revolute), metres (prismatic).
UNBOUNDED_HALF_WIDTH = {"revolute": math.pi, "prismatic": 1.0}
DEFAULT_N = 100_000
URDF_SUFFIXES = (".urdf", ".xml")
OUTPUT_FORMATS = ("npz", "csv")


class UsageError(Exception):
    """A mistake in the command line or its values: reported in one line, exit code 2."""


class _Parser(argparse.ArgumentParser):
    # Values such as -1e-3 or -0.4,0.6 (a --q list) are numbers, not options: argparse's own
    # pattern knows only -1 and -0.4.
    _NEGATIVE_NUMBERS = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?(,[-+.\deE,\s]*)?$")

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = self._NEGATIVE_NUMBERS

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

configurations file (--configurations PATH, instead of sampling):
  .npz: an array q of shape (N, dof) (or (dof,) for one configuration) and optionally qd of the
  same shape. .csv (any other suffix): one configuration per line, comma-separated; lines
  starting with # are comments. Without a header line a row holds dof values (q) or 2 dof values
  (q then qd), in robot.joint_names order. With a header line, its columns are joint names
  (or q_<joint>) and optionally qd_<joint>, in any order. Without qd in the file, qd is sampled as
  above. Values outside the joint limits are used as given and counted in the summary.

output (written to a temporary file in the same directory, then renamed):
  --format npz (default; also chosen by an --output ending in .npz): q (N, dof), qd (N, dof),
  twist (N, 6) = J @ qd, J (N, 6, dof) geometric at --reference, Ja (N, 6, dof) analytical
  d[p; phi]/dq, margin (N,), sigma (N, min(6, dof)); metadata robot, joint_names, frame,
  reference, representation, dtype, seed, qd_scale, singular_tol, jaxkin_version.
  --format csv (also chosen by an --output ending in .csv): one line per configuration with
  columns q_<joint>, qd_<joint>, vx, vy, vz, wx, wy, wz (the twist), sigma_1 ... sigma_k, margin,
  after # comment lines holding the metadata; J and Ja are in the .npz only.
  Rows of J and twist are [v; omega].
"""


_ROBOT_HELP = "zoo name, erd/<name> (example-robot-data) or a URDF file path; see 'jaxkin robots'"

_JACOBIAN_EPILOG = """\
rows and columns:
  geometric (default): rows vx vy vz [m/s] and wx wy wz [rad/s] per unit joint rate: the twist
  [v; omega] = J @ qd. --reference world_aligned: v is the velocity of the frame's origin (or
  --point), both in world axes (the textbook's J; Pinocchio LOCAL_WORLD_ALIGNED, RTB jacob0);
  local: the same point, in the frame's own axes; world: v of the body point at the world origin.
  --analytical REPR: rows x y z and the three angles of REPR (rpy: roll pitch yaw of
  R = Rz(yaw) Ry(pitch) Rx(roll)); the derivative d[p; phi]/dq. Columns follow robot.joint_names;
  a column is per rad/s (revolute joint) or per m/s (prismatic).

examples:
  jaxkin jacobian niryo_one --q 0 -0.5 0.3 0 0.4 0
  jaxkin jacobian puma560 --config qn --reference local --format csv
  jaxkin jacobian robot.urdf --tip tool0 --q 0.1,0.2,0.3,0.4,0.5,0.6 --analytical rpy
"""


def _add_robot_options(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--tip",
        metavar="LINK",
        help="URDF robots: keep only the chain from --base to this link (the default frame)",
    )
    p.add_argument("--base", metavar="LINK", help="URDF robots: the link taken as the world frame")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="jaxkin",
        description="Differential kinematics of robot manipulators in JAX.",
    )
    parser.add_argument("--version", action="version", version=f"jaxkin {jk.__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    robots = sub.add_parser(
        "robots",
        help="list the robot zoo and the URDF robots that load by name",
        description=(
            "List the zoo (name and description), then the example-robot-data URDFs that load\n"
            "by name (erd/..., when example-robot-data is installed). Any URDF file also works\n"
            "as ROBOT: give its path."
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    robots.add_argument("--zoo", action="store_true", help="list only the zoo")
    robots.set_defaults(handler=cmd_robots)

    jac = sub.add_parser(
        "jacobian",
        help="print the Jacobian of one configuration",
        description=(
            "Print the 6 x dof Jacobian of one configuration, rows labelled, columns named by\n"
            "joint, with its frame, reference (which point's velocity, in which axes) and row\n"
            "order stated. Geometric by default: [v; omega] = J @ qd."
        ),
        epilog=_JACOBIAN_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    jac.set_defaults(handler=cmd_jacobian)
    jac.add_argument("robot", metavar="ROBOT", help=_ROBOT_HELP)
    where = jac.add_mutually_exclusive_group()
    where.add_argument(
        "--q",
        nargs="+",
        metavar="VALUE",
        help="joint values, one per joint in robot.joint_names order (rad or m); spaces or "
        "commas between them (default: all zero)",
    )
    where.add_argument(
        "--config", metavar="NAME", help="a named configuration of a zoo robot (e.g. home, qr)"
    )
    jac.add_argument(
        "--frame",
        type=_frame,
        default=None,
        help="frame name or index (default: the tip, tool included)",
    )
    jac.add_argument(
        "--point",
        nargs=3,
        type=float,
        metavar=("X", "Y", "Z"),
        help="the point whose velocity the linear rows give, as an offset from the frame's "
        "origin in the frame's axes (m; default: the origin)",
    )
    jac.add_argument(
        "--reference",
        choices=REFERENCES,
        default="world_aligned",
        help="point and basis of a geometric Jacobian (default: %(default)s)",
    )
    jac.add_argument(
        "--analytical",
        choices=REPRESENTATIONS,
        metavar="REPR",
        help="print the analytical Jacobian d[p; phi]/dq instead, phi in REPR "
        f"({', '.join(REPRESENTATIONS)})",
    )
    jac.add_argument(
        "--format",
        choices=("text", "csv", "json"),
        default="text",
        help="output format (default: %(default)s)",
    )
    jac.add_argument(
        "--digits", type=_positive_int, default=4, help="decimals in text output (default: 4)"
    )
    _add_robot_options(jac)
    jac.add_argument(
        "--dtype",
        choices=("float32", "float64"),
        default="float64",
        help="float precision (default: %(default)s)",
    )

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
        help=_ROBOT_HELP + " (default: %(default)s)",
    )
    _add_robot_options(vel)
    count = vel.add_mutually_exclusive_group()
    count.add_argument(
        "--n",
        type=_positive_int,
        default=None,
        help=f"configurations to sample (default: {DEFAULT_N})",
    )
    count.add_argument(
        "--configurations",
        metavar="PATH",
        help="read q (and optionally qd) from a .npz or .csv file instead of sampling; see below",
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
        help="output file (default: velocities_<robot>_<n>.<format> in the current directory)",
    )
    out.add_argument("--no-output", action="store_true", help="compute and summarise only")
    vel.add_argument(
        "--format",
        choices=OUTPUT_FORMATS,
        default=None,
        help="output format (default: from the --output suffix, else npz; see below)",
    )
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
        return _usage_error(
            "choose a command: velocities, jacobian or robots (see 'jaxkin --help')"
        )
    try:
        return args.handler(args)
    except (UsageError, jk.JaxkinError) as e:
        return _usage_error(str(e))
    except KeyboardInterrupt:
        print("jaxkin: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # e.g. 'jaxkin robots | head': the reader left; stop quietly
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 141


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
    if args.zoo:
        return 0
    urdf = _urdf_robot_names()
    print()
    if urdf:
        print(f"# {len(urdf)} URDF robots of example-robot-data, loaded by name (e.g. {urdf[0]}):")
        for name in urdf:
            print(name)
    else:
        print("# URDF robots: install example-robot-data for more by name (erd/...)")
    print("# any URDF file also works as ROBOT: give its path")
    return 0


def _urdf_robot_names() -> list[str]:
    """The example-robot-data names the zoo offers, [] when this jaxkin or the package lacks it."""
    erd_names = getattr(jk.robots, "erd_names", None)
    return list(erd_names()) if erd_names is not None else []


def load_robot(spec: str, dtype: str, tip: str | None = None, base: str | None = None):
    """The robot ``spec`` names: a URDF path, a zoo name or an ``erd/...`` name.

    Names win over files: a file called like a zoo robot needs a path (``./niryo_one``). Returns
    ``(robot, label)``; ``label`` names output files. Every user mistake is a
    :class:`UsageError` or a :class:`jaxkin.JaxkinError` (a bad file's message names it).
    """
    zoo = jk.robots.names()
    urdf = _urdf_robot_names()
    if spec not in zoo and spec not in urdf:
        path = pathlib.Path(spec)
        if spec.lower().endswith(URDF_SUFFIXES) or os.sep in spec or path.exists():
            return _load_urdf_file(path, dtype, tip, base), path.stem
        more = f" or one of {len(urdf)} erd/... URDF robots" if urdf else ""
        raise UsageError(
            f"unknown robot {spec!r}; choose one of {', '.join(zoo)}{more}, or give a URDF file "
            "path (see 'jaxkin robots')"
        )
    options = {k: v for k, v in (("tip", tip), ("base", base)) if v is not None}
    if options and spec in zoo:
        raise UsageError(
            f"--tip and --base apply to URDF robots; {spec!r} is a zoo model (use --frame)"
        )
    return jk.robots.load(spec, dtype=dtype, **options), spec.replace("/", "_")


def _load_urdf_file(path: pathlib.Path, dtype: str, tip: str | None, base: str | None):
    load_urdf = getattr(jk, "load_urdf", None)
    if load_urdf is None:
        raise UsageError(
            f"cannot load {path}: this jaxkin {jk.__version__} has no URDF support (jk.load_urdf); "
            "use a zoo robot (see 'jaxkin robots')"
        )
    if not path.exists():
        raise UsageError(f"no such URDF file: {path}")
    if not path.is_file():
        raise UsageError(f"{path} is not a file; give the path of a .urdf file")
    try:
        return load_urdf(path, tip=tip, base=base, dtype=dtype)
    except OSError as e:
        raise UsageError(f"cannot read {path}: {e.strerror or e}") from None


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

    def commit(self, arrays: dict[str, np.ndarray], fmt: str = "npz") -> None:
        """Write ``arrays`` (``np.savez``, or :func:`_write_csv` for ``fmt="csv"``), then rename."""
        if self.tmp is None:
            raise RuntimeError("AtomicOutput.commit must be called once, inside its 'with' block")
        try:
            with open(self.tmp, "wb") as f:
                if fmt == "csv":
                    _write_csv(f, arrays)
                else:
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
    with _x64(args.dtype == "float64"):
        robot, label = load_robot(args.robot, args.dtype, args.tip, args.base)
        frame_name = robot.frame_names[robot.frame_index(args.frame)]
        dtype = np.dtype(args.dtype)
        if args.configurations is not None:
            q, qd = read_configurations(args.configurations, robot, dtype)
            qd_from_file = qd is not None
            if qd is None:
                _, qd = sample_configurations(robot, len(q), args.seed, args.qd_scale, dtype)
        else:
            q, qd = sample_configurations(
                robot, args.n or DEFAULT_N, args.seed, args.qd_scale, dtype
            )
            qd_from_file = False
        fmt = args.format
        if fmt is None:
            suffix = pathlib.Path(args.output or "").suffix.lower().lstrip(".")
            fmt = suffix if suffix in OUTPUT_FORMATS else "npz"
        source = (args.configurations, qd_from_file)
        if args.no_output:
            return _velocities(args, robot, frame_name, q, qd, source, None, fmt)
        path = args.output or f"velocities_{label}_{len(q)}.{fmt}"
        with AtomicOutput(path) as output:
            return _velocities(args, robot, frame_name, q, qd, source, output, fmt)


def read_configurations(path: str, robot: jk.Robot, dtype: Any):
    """``(q, qd)`` from a .npz (arrays ``q``, optional ``qd``) or CSV file; ``qd`` may be None.

    Shapes (N, dof) in ``robot.joint_names`` order; see ``jaxkin velocities --help`` for the
    CSV layout. Every problem with the file is a :class:`UsageError` naming it.
    """
    p = pathlib.Path(path)
    if not p.is_file():
        raise UsageError(
            f"configurations file {path} " + ("is not a file" if p.exists() else "does not exist")
        )
    try:
        if p.suffix.lower() == ".npz":
            q, qd = _read_npz(p, robot)
        else:
            q, qd = _read_csv(p, robot)
    except OSError as e:
        raise UsageError(f"cannot read {path}: {e.strerror or e}") from None
    for name, a in (("q", q), ("qd", qd)):
        if a is None:
            continue
        bad = np.flatnonzero(~np.all(np.isfinite(a), axis=1))
        if bad.size:
            raise UsageError(
                f"{path}: {name} of configuration {int(bad[0])} is not finite: {a[bad[0]].tolist()}"
            )
    if len(q) == 0:
        raise UsageError(f"{path} holds no configurations")
    return q.astype(dtype), None if qd is None else qd.astype(dtype)


def _joint_shape_error(path, what: str, got: tuple, robot: jk.Robot) -> UsageError:
    return UsageError(
        f"{path}: {what} has shape {got}; robot {robot.name!r} has {robot.dof} joints "
        f"({', '.join(robot.joint_names)}), so it must be (N, {robot.dof})"
    )


def _read_npz(p: pathlib.Path, robot: jk.Robot):
    import zipfile

    if not zipfile.is_zipfile(p):
        raise UsageError(f"{p} is not an .npz file (numpy.savez writes one); or use a .csv file")
    try:
        with np.load(p, allow_pickle=False) as f:
            arrays = {k: f[k] for k in f.files}
    except (ValueError, zipfile.BadZipFile, EOFError) as e:
        raise UsageError(f"cannot read {p} as .npz: {e}") from None
    if "q" not in arrays:
        raise UsageError(
            f"{p} has no array 'q' (it has {sorted(arrays) or 'none'}); save q of shape (N, dof)"
        )
    out = []
    for name in ("q", "qd"):
        a = arrays.get(name)
        if a is None:
            out.append(None)
            continue
        if not (np.issubdtype(a.dtype, np.floating) or np.issubdtype(a.dtype, np.integer)):
            raise UsageError(f"{p}: {name} must hold numbers, got dtype {a.dtype}")
        a = a.astype(np.float64)
        if a.ndim == 1:
            a = a[None]
        if a.ndim != 2 or a.shape[1] != robot.dof:
            raise _joint_shape_error(p, name, arrays[name].shape, robot)
        out.append(a)
    if out[1] is not None and out[1].shape != out[0].shape:
        raise UsageError(
            f"{p}: qd has shape {out[1].shape} but q has {out[0].shape}; they must match"
        )
    return out[0], out[1]


def _read_csv(p: pathlib.Path, robot: jk.Robot):
    names = list(robot.joint_names)
    header, rows = None, []
    with open(p, encoding="utf-8", errors="replace") as f:
        for lineno, line in enumerate(f, start=1):
            text = line.strip()
            if not text or text.startswith("#"):
                continue
            fields = [x.strip() for x in text.split(",")]
            try:
                rows.append((lineno, [float(x) for x in fields]))
            except ValueError:
                if header is None and not rows:
                    header = fields
                    continue
                raise UsageError(
                    f"{p} line {lineno}: not a row of numbers: {text[:80]!r}"
                ) from None
    if header is not None:
        columns = {}
        for k, h in enumerate(header):
            key = h[2:] if h.startswith("q_") and h[2:] in names else h
            if key in names:
                columns[("q", key)] = k
            elif h.startswith("qd_") and h[3:] in names:
                columns[("qd", h[3:])] = k
            else:
                raise UsageError(
                    f"{p}: unknown column {h!r}; columns are joint names {names} (or q_<joint>) "
                    "and optionally qd_<joint>"
                )
        missing = [n for n in names if ("q", n) not in columns]
        if missing:
            raise UsageError(f"{p}: no column for joint(s) {missing} of robot {robot.name!r}")
        has_qd = any(k[0] == "qd" for k in columns)
        if has_qd and not all(("qd", n) in columns for n in names):
            raise UsageError(f"{p}: give qd_<joint> for every joint {names} or for none")
        order = [columns[("q", n)] for n in names]
        if has_qd:
            order += [columns[("qd", n)] for n in names]
        width = len(header)
    else:
        order, width = None, None
    table = []
    for lineno, values in rows:
        if width is not None and len(values) != width:
            raise UsageError(f"{p} line {lineno}: {len(values)} values, the header has {width}")
        if width is None and len(values) not in (robot.dof, 2 * robot.dof):
            raise UsageError(
                f"{p} line {lineno}: {len(values)} values; robot {robot.name!r} has {robot.dof} "
                f"joints ({', '.join(names)}): give {robot.dof} (q) or {2 * robot.dof} (q, qd)"
            )
        table.append([values[k] for k in order] if order is not None else values)
    if not table:
        raise UsageError(f"{p} holds no configurations")
    if width is None and len({len(r) for r in table}) > 1:
        raise UsageError(f"{p}: rows mix {robot.dof} and {2 * robot.dof} values; use one layout")
    a = np.array(table, dtype=np.float64)
    if a.shape[1] == 2 * robot.dof:
        return a[:, : robot.dof], a[:, robot.dof :]
    return a, None


def _velocities(
    args: argparse.Namespace,
    robot: jk.Robot,
    frame_name: str,
    q: np.ndarray,
    qd: np.ndarray,
    source: tuple[str | None, bool],
    output: AtomicOutput | None,
    fmt: str,
) -> int:
    n = len(q)
    fn = velocity_kernel(robot, frame_name, args.reference, args.representation)
    if args.progress is None:
        show = n >= PROGRESS_MIN_N
        bar = ProgressBar(n, "velocities", unit="cfg", enabled=show)
    else:
        bar = ProgressBar(n, "velocities", unit="cfg", enabled=args.progress, force=True)
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
        output.commit(arrays, fmt)

    pct = lambda k: 100.0 * k / n  # noqa: E731
    margin_name = {"rpy": "|cos(pitch)|", "zyz": "|sin(theta)|", "rotvec": "1 - |w|/(2 pi)"}
    lines = [
        f"robot            {robot.name} ({robot.dof} dof: {', '.join(robot.joint_names)})",
        f"frame            {frame_name}, reference {args.reference}, "
        f"representation {args.representation}",
        f"configurations   {_source_line(args, robot, q, source)}",
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


def _source_line(args: argparse.Namespace, robot: jk.Robot, q: np.ndarray, source) -> str:
    path, qd_from_file = source
    sampled_qd = (
        f"qd uniform in [-{args.qd_scale:g}, {args.qd_scale:g}] rad/s or m/s, seed {args.seed}"
    )
    if path is None:
        return f"{len(q):,} (seed {args.seed}, {sampled_qd.replace(f', seed {args.seed}', '')})"
    lo, hi = np.asarray(robot.lower), np.asarray(robot.upper)
    outside = int(np.count_nonzero(np.any((q < lo) | (q > hi), axis=1)))
    qd_text = "qd from the file" if qd_from_file else sampled_qd
    return f"{len(q):,} from {path} ({qd_text}; {outside:,} outside the joint limits)"


def _write_csv(f, arrays: dict[str, np.ndarray]) -> None:
    """One line per configuration: q_*, qd_*, the twist, sigma_*, margin; metadata as comments."""
    joints = [str(j) for j in arrays["joint_names"]]
    meta = [
        "robot", "frame", "reference", "representation", "dtype", "seed", "qd_scale",
        "singular_tol", "jaxkin_version",
    ]  # fmt: skip
    lines = [f"# jaxkin velocities: {k} = {arrays[k]}" for k in meta]
    lines.append("# twist [vx vy vz wx wy wz] = J @ qd; J and Ja are written by --format npz only")
    k = arrays["sigma"].shape[1]
    header = (
        [f"q_{j}" for j in joints]
        + [f"qd_{j}" for j in joints]
        + ["vx", "vy", "vz", "wx", "wy", "wz"]
        + [f"sigma_{i + 1}" for i in range(k)]
        + ["margin"]
    )
    table = np.concatenate(
        [arrays["q"], arrays["qd"], arrays["twist"], arrays["sigma"], arrays["margin"][:, None]],
        axis=1,
    )
    digits = 17 if table.dtype == np.float64 else 9
    f.write(("\n".join(lines) + "\n" + ",".join(header) + "\n").encode())
    np.savetxt(f, table, fmt=f"%.{digits}g", delimiter=",")


# ---------------------------------------------------------------------- jacobian
def cmd_jacobian(args: argparse.Namespace) -> int:
    with _x64(args.dtype == "float64"):
        robot, _ = load_robot(args.robot, args.dtype, args.tip, args.base)
        q = _joint_values(args, robot)
        frame = robot.frame_names[robot.frame_index(args.frame)]
        if args.analytical:
            J = jk.analytical_jacobian(robot, q, args.analytical, frame=frame, point=args.point)
        else:
            J = jk.geometric_jacobian(
                robot, q, frame=frame, point=args.point, reference=args.reference
            )
        J = np.asarray(J, dtype=np.float64)
    kind = "analytical" if args.analytical else "geometric"
    if args.format == "json":
        print(json.dumps(_jacobian_record(J, robot, frame, q, args, kind), indent=1))
    elif args.format == "csv":
        rows = _row_labels(args.analytical)
        print(",".join(["row", *robot.joint_names]))
        for label, row in zip(rows, J, strict=True):
            print(",".join([label, *(repr(float(x)) for x in row)]))
    else:
        print(format_jacobian(J, robot, frame, q, args.reference, args.analytical, args.digits,
                              args.point))  # fmt: skip
        if not np.any(J):
            print(
                f"note: no joint moves frame {frame!r}; choose another with --frame (frames: "
                f"{', '.join(robot.frame_names)}) or, for a URDF robot, --tip"
            )
    return 0


def _joint_values(args: argparse.Namespace, robot: jk.Robot) -> np.ndarray:
    if args.config is not None:
        configs = robot.configurations
        if args.config not in configs:
            raise UsageError(
                f"robot {robot.name!r} has no configuration {args.config!r}; it has "
                f"{sorted(configs) or 'none'} (or give --q)"
            )
        return np.asarray(configs[args.config], dtype=np.float64)
    if args.q is None:
        return np.zeros(robot.dof)
    texts = [t for item in args.q for t in item.replace(",", " ").split()]
    values = []
    for t in texts:
        try:
            values.append(float(t))
        except ValueError:
            raise UsageError(f"--q: {t!r} is not a number") from None
    if len(values) != robot.dof:
        raise UsageError(
            f"robot {robot.name!r} has {robot.dof} joints ({', '.join(robot.joint_names)}); "
            f"--q gave {len(values)} value{'s' if len(values) != 1 else ''}"
        )
    q = np.array(values)
    if not np.all(np.isfinite(q)):
        raise UsageError(f"--q must be finite numbers, got {values}")
    return q


def _row_labels(representation: str | None) -> list[str]:
    if representation is None:
        return ["vx", "vy", "vz", "wx", "wy", "wz"]
    angles = {"rpy": ["roll", "pitch", "yaw"], "zyz": ["phi", "theta", "psi"]}
    return ["x", "y", "z", *angles.get(representation, ["wx_rotvec", "wy_rotvec", "wz_rotvec"])]


def _jacobian_header(robot, frame, q, reference, representation, point) -> list[str]:
    at = "its origin" if point is None else f"the point {list(point)} m (frame axes) on it"
    if representation is None:
        meaning = {
            "world_aligned": f"velocity of {at}, world axes",
            "local": f"velocity of {at}, the frame's own axes",
            "world": "velocity of the body point at the world origin, world axes",
        }[reference]
        what = (
            f"geometric Jacobian, reference {reference}: [v; omega] = J @ qd, v = {meaning}, "
            "omega in the same axes"
        )
    else:
        what = {
            "rpy": "analytical Jacobian d[p; phi]/dq, phi = (roll, pitch, yaw) of "
            "R = Rz(yaw) Ry(pitch) Rx(roll)",
            "zyz": "analytical Jacobian d[p; phi]/dq, phi = (phi, theta, psi) of "
            "R = Rz(phi) Ry(theta) Rz(psi)",
            "rotvec": "analytical Jacobian d[p; w]/dq, w the rotation vector (R = exp(skew(w)))",
        }[representation] + f"; p = {at}, world axes"
    tip = " (the tip)" if robot.frame_index(frame) == robot.tip_frame else ""
    units = ["rad" if k == "revolute" else "m" for k in robot.joint_kinds]
    q_text = ", ".join(
        f"{n}={v:g} {u}" for n, v, u in zip(robot.joint_names, q, units, strict=True)
    )
    return [
        f"robot  {robot.name} ({robot.dof} joints), frame {frame}{tip}",
        f"q      {q_text}",
        f"J      {what}",
    ]


def format_jacobian(
    J: np.ndarray,
    robot: jk.Robot,
    frame: str,
    q: np.ndarray,
    reference: str = "world_aligned",
    representation: str | None = None,
    digits: int = 4,
    point: Any = None,
) -> str:
    """A (6, dof) Jacobian as a labelled text table, with what it means stated above it."""
    rows = _row_labels(representation)
    linear = "m/s" if representation is None else "m"
    angular = "rad/s" if representation is None else "rad"
    units = [linear] * 3 + [angular] * 3
    labels = [f"{r} [{u}]" for r, u in zip(rows, units, strict=True)]
    cells = [[_number(x, digits) for x in row] for row in J]
    width = max(max(len(n) for n in robot.joint_names), max(len(c) for r in cells for c in r))
    lw = max(len(s) for s in labels)
    lines = _jacobian_header(robot, frame, q, reference, representation, point)
    if representation is None:
        per = "per unit joint rate: a column is per rad/s (revolute joint) or per m/s (prismatic)"
    else:
        per = "derivatives: a column is per rad (revolute joint) or per m (prismatic)"
    lines.append(f"rows   {' '.join(rows)} ({per})")
    lines.append("")
    lines.append(" " * lw + "  " + " ".join(f"{n:>{width}}" for n in robot.joint_names))
    for label, row in zip(labels, cells, strict=True):
        lines.append(f"{label:<{lw}}  " + " ".join(f"{c:>{width}}" for c in row))
    return "\n".join(lines)


def _number(x: float, digits: int) -> str:
    text = f"{x:.{digits}f}"
    return text.replace("-", "", 1) if float(text) == 0 else text  # no "-0.0000"


def _jacobian_record(J, robot, frame, q, args, kind) -> dict[str, Any]:
    return {
        "robot": robot.name,
        "frame": frame,
        "kind": kind,
        "reference": None if args.analytical else args.reference,
        "representation": args.analytical,
        "point": args.point,
        "rows": _row_labels(args.analytical),
        "columns": list(robot.joint_names),
        "q": [float(x) for x in q],
        "J": [[float(x) for x in row] for row in J],
        "jaxkin_version": jk.__version__,
    }
