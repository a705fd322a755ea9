"""The ``jaxkin`` command line.

* ``jaxkin robots`` lists the zoo, the example-robot-data URDFs and the MJCF models of installed
  packages that load by name.
* ``jaxkin jacobian ROBOT --q ...`` prints the geometric (or analytical) Jacobian of one
  configuration as a labelled table, stating its frame, reference and row order.
* ``jaxkin velocities [ROBOT] --n N`` samples N configurations
  (:func:`jaxkin.sample_configurations`, block by block) and joint velocities (or reads them
  from a CSV/NPZ file with
  ``--configurations``) and computes for each, from one forward pass, the hand-built geometric
  Jacobian, the twist ``J @ qd``, the analytical Jacobian with its representation margin and the
  singular values of ``J``, in compiled chunks (:func:`jaxkin.batch.chunked_map`), streaming them
  to an ``.npz`` or ``.csv`` file (:class:`jaxkin.io.ResultWriter`); the first
  ``CHECK_ROWS`` configurations are also checked against autodiff (``jax.jacfwd``). Prints a
  summary.

ROBOT is a zoo name (``jaxkin robots``), an example-robot-data name (``erd/panda``), an MJCF model
name (``mjcf/...``) or the path of a URDF or MJCF file (an ``.xml`` file whose root element is
``<mujoco>`` loads with :func:`jaxkin.load_mjcf`). A ``.xacro`` file is a program (its ``${...}``
expressions run Python): it is expanded only with ``--trust-xacro``.

Library errors advise Python keywords (``frame=``, ``tip=``, ``trust=True``); the command line
reports them with its own flags instead (``--frame``, ``--tip``, ``--trust-xacro``).

The command line turns float64 on (``--dtype float64``, the default, enables
``jax_enable_x64`` for the command); the library follows JAX's float32 default.

Exit codes: 0 success; 1 a check failed (the hand-built and autodiff Jacobians disagree, or a
result is not finite); 2 a usage error (one line on stderr starting ``jaxkin: error:``); 130
interrupted (143 on SIGTERM).
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import json
import math
import os
import pathlib
import re
import sys
from collections.abc import Iterator, Sequence
from typing import Any

import jax
import numpy as np

import jaxkin as jk

from .batch import MapStats, ProgressBar, chunked_map
from .io import MAX_INPUT_BYTES, ResultWriter, csv_record, read_configurations
from .jacobians import REFERENCES
from .representations import REPRESENTATIONS
from .robots.files import NAME_PREFIXES, XACRO_SUFFIX
from .sampling import SAMPLE_BLOCK, sample_rows
from .velocity import velocity_results

__all__ = [
    "format_jacobian",
    "load_robot",
    "main",
]

PROGRESS_MIN_N = 200_000
# Rows per compiled call. Smaller than chunked_map's default: this kernel (a Jacobian pass and an
# SVD per row) has many intermediates, and on a 2-core CPU 4096 rows ran 1.5 - 2x faster than
# 65536 (their working set stays in cache).
CLI_CHUNK_SIZE = 4096
CHECK_TOL = {"float64": 1e-10, "float32": 1e-4}
CHECK_ROWS = 1000  # configurations checked against autodiff (jax.jacfwd)
DEFAULT_N = 100_000
NORM_SAMPLE = 1 << 24  # twist norms kept for the median and p99 (every k-th row beyond)
# Caps: beyond them a run would take days, exhaust memory or print nonsense.
MAX_N = 100_000_000
MAX_CHUNK = 1 << 20
MAX_DIGITS = 17  # float64 round-trips with 17 significant digits; more print noise
MAX_SEED = 2**32 - 1
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
def _integer(text: str, lo: int, hi: int) -> int:
    """An integer in ``[lo, hi]``; ``1_000_000`` and ``1e6`` are accepted."""
    try:
        value = int(text)
    except ValueError:
        try:
            number = float(text)
        except ValueError:
            number = math.nan
        if not (math.isfinite(number) and number.is_integer()):
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        value = int(number)
    if not lo <= value <= hi:
        raise argparse.ArgumentTypeError(f"expected an integer from {lo} to {hi:,}, got {text!r}")
    return value


def _count(text: str) -> int:
    return _integer(text, 1, MAX_N)


def _chunk(text: str) -> int:
    return _integer(text, 1, MAX_CHUNK)


def _digits(text: str) -> int:
    return _integer(text, 0, MAX_DIGITS)


def _seed(text: str) -> int:
    return _integer(text, 0, MAX_SEED)


def _real(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
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
_GIB = MAX_INPUT_BYTES / 2**30
_VELOCITIES_EPILOG = f"""\
sampling:
  q is uniform within each joint's limits (jaxkin.sample_configurations); an unbounded side
  (infinite, or |limit| >= 1e6 such as +-1.79e308) is taken as -pi/pi rad for a revolute joint
  and -1/1 m for a prismatic one (or the finite side -/+ 2 pi rad, 2 m). qd is uniform in
  [-s, s] rad/s (revolute) or m/s (prismatic), s = --qd-scale. Both are drawn in blocks of
  {SAMPLE_BLOCK:,} rows, block b from jax.random.fold_in(key(--seed), b): a configuration depends
  on the seed and its index only, and they never all sit in memory.

near-singularity criteria (tol = --singular-tol):
  kinematic:       sigma_min / sigma_max < tol, the singular values of the 6 x dof geometric
                   Jacobian J (min(6, dof) of them), i.e. J is numerically rank deficient. J mixes
                   m/rad and rad/rad rows, so the ratio depends on the unit of length; a frame
                   moved by fewer than min(6, dof) joints counts as singular everywhere.
  representation:  margin < tol, where margin is the distance of the frame's orientation from the
                   representation's singularity: |cos(pitch)| for rpy, |sin(theta)| for zyz,
                   1 - |w| / (2 pi) for rotvec. The analytical Jacobian grows like 1 / margin.

check (the first {CHECK_ROWS:,} configurations; all run the same hand-built kernel):
  max |J_handbuilt - J_jacfwd| over all their entries must be at most
  {CHECK_TOL["float64"]:g} (float64) or {CHECK_TOL["float32"]:g} (float32); otherwise FAIL, exit 1.
  Every result must be finite, and some joint must move the frame (a Jacobian not all zero):
  otherwise exit 1 (or 2, for the frame, before the run) and no output file.

limits (larger values are refused in one line, exit 2):
  --n at most {MAX_N:,} per run (and the output must fit the free disk); --chunk-size at most
  {MAX_CHUNK:,}; --seed from 0 to {MAX_SEED:,}; jacobian --digits at most {MAX_DIGITS}.
  --configurations: a CSV file or standard input at most {_GIB:g} GiB (MAX_INPUT_BYTES: standard
  input is read up to it, never further); of an .npz only q and qd are read, each at most
  {_GIB:g} GiB as declared (the zip member's size and its .npy header's shape x itemsize),
  checked before it is decompressed.

robot files:
  a .urdf file, an MJCF .xml file (root element <mujoco>: jaxkin.load_mjcf; any other .xml is
  read as URDF), or a .xacro file with --trust-xacro only: xacro files are programs, and their
  ${{...}} expressions run Python that nothing sandboxes (without the flag they are refused;
  or expand one yourself: xacro robot.urdf.xacro > robot.urdf).

precision:
  --dtype float64 (the default) turns jax_enable_x64 on for this run; the library follows JAX's
  float32 default. The summary's dtype line says which was used.

configurations file (--configurations PATH, instead of sampling):
  .npz: an array q of shape (N, dof) (or (dof,) for one configuration) and optionally qd of the
  same shape. .csv (any other suffix): one configuration per line, comma-separated (quoted
  fields and a UTF-8 byte order mark, as Excel and R write, are fine); lines starting with # are
  comments. Without a header line a row holds dof values (q) or 2 dof values (q then qd), in
  robot.joint_names order. With a header line, its columns are joint names (or q_<joint>) and
  optionally qd_<joint>, in any order, each once (a first column with an empty name, R's row
  names, is skipped). Without qd in the file, qd is sampled as above. Values outside the joint
  limits are used as given and counted in the summary. PATH - reads standard input.

output (streamed chunk by chunk to a temporary .<name>.<random>.tmp in the same directory, then
flushed and renamed; interrupted or failed runs leave no file; --output - writes csv to standard
output and the summary to stderr):
  --format npz (default; also chosen by an --output ending in .npz): q (N, dof), qd (N, dof),
  twist (N, 6) = J @ qd, J (N, 6, dof) geometric at --reference, Ja (N, 6, dof) analytical
  d[p; phi]/dq, margin (N,), sigma (N, min(6, dof)); metadata robot, joint_names, frame,
  reference, representation, dtype, seed, qd_scale, singular_tol, jaxkin_version.
  --format csv (also chosen by an --output ending in .csv; a --format contradicting the
  --output suffix is refused): one line per configuration with
  columns q_<joint>, qd_<joint>, vx, vy, vz, wx, wy, wz (the twist), sigma_1 ... sigma_k, margin,
  after # comment lines holding the metadata; J and Ja are in the .npz only.
  Rows of J and twist are [v; omega].
"""


_ROBOT_HELP = (
    "zoo name, erd/<name> (example-robot-data), mjcf/<name>, or a URDF file path (an MJCF .xml "
    "file, a .xacro with --trust-xacro); see 'jaxkin robots'"
)

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
    p.add_argument(
        "--trust-xacro",
        action="store_true",
        help="expand a .xacro ROBOT file with the xacro package. A xacro file is a program (its "
        "${...} expressions run Python, which no sandbox contains): pass this only for files you "
        "trust; without it a .xacro file is refused (or expand it yourself: xacro robot.urdf.xacro "
        "> robot.urdf)",
    )


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="jaxkin",
        description="Differential kinematics of robot manipulators in JAX.",
    )
    parser.add_argument("--version", action="version", version=f"jaxkin {jk.__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    _add_robots_parser(sub)
    _add_jacobian_parser(sub)
    _add_velocities_parser(sub)
    return parser


def _add_frame_option(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--frame",
        type=_frame,
        default=None,
        help="frame name or index (default: the tip, tool included)",
    )


def _add_reference_option(p: argparse.ArgumentParser, help_text: str) -> None:
    p.add_argument("--reference", choices=REFERENCES, default="world_aligned", help=help_text)


def _add_dtype_option(p: argparse.ArgumentParser, help_text: str) -> None:
    p.add_argument("--dtype", choices=("float32", "float64"), default="float64", help=help_text)


# ---------------------------------------------------------------------- parser: robots
def _add_robots_parser(sub: Any) -> None:
    robots = sub.add_parser(
        "robots",
        help="list the robot zoo and the URDF robots that load by name",
        description=(
            "List the zoo (name and description), then the example-robot-data URDFs that load\n"
            "by name (erd/..., when example-robot-data is installed) and the MJCF models of\n"
            "installed packages (mjcf/..., dm-control, gymnasium-robotics). Any URDF or MJCF\n"
            "file also works as ROBOT: give its path."
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    robots.add_argument("--zoo", action="store_true", help="list only the zoo")
    robots.set_defaults(handler=cmd_robots)


# ---------------------------------------------------------------------- parser: jacobian
def _add_jacobian_parser(sub: Any) -> None:
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
    _add_frame_option(jac)
    _add_jacobian_kind_options(jac)
    jac.add_argument(
        "--format",
        choices=("text", "csv", "json"),
        default="text",
        help="output format (default: %(default)s)",
    )
    jac.add_argument(
        "--digits",
        type=_digits,
        default=4,
        help=f"decimals in text output, 0 to {MAX_DIGITS} (default: %(default)s)",
    )
    _add_robot_options(jac)
    _add_dtype_option(
        jac, "float precision (default: %(default)s; float64 enables jax_enable_x64 for this run)"
    )


def _add_jacobian_kind_options(jac: argparse.ArgumentParser) -> None:
    """``--point``, ``--reference`` and ``--analytical``: which Jacobian to print."""
    jac.add_argument(
        "--point",
        nargs=3,
        type=_real,
        metavar=("X", "Y", "Z"),
        help="the point whose velocity the linear rows give, as an offset from the frame's "
        "origin in the frame's axes (m; default: the origin)",
    )
    _add_reference_option(jac, "point and basis of a geometric Jacobian (default: %(default)s)")
    jac.add_argument(
        "--analytical",
        choices=REPRESENTATIONS,
        metavar="REPR",
        help="print the analytical Jacobian d[p; phi]/dq instead, phi in REPR "
        f"({', '.join(REPRESENTATIONS)})",
    )


# ---------------------------------------------------------------------- parser: velocities
def _add_velocities_parser(sub: Any) -> None:
    vel = sub.add_parser(
        "velocities",
        help="batched Jacobians and end-effector twists of sampled configurations",
        description=(
            "Sample N configurations and joint velocities of a robot; compute from one forward\n"
            "pass the geometric Jacobian (hand-built; the first configurations checked against\n"
            "jax.jacfwd), the twist J @ qd, the analytical Jacobian and the singular values of\n"
            "J; stream them to an .npz or .csv file and print a summary naming the frame."
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
    _add_velocities_input_options(vel)
    _add_velocities_output_options(vel)
    _add_velocities_kernel_options(vel)


def _add_velocities_input_options(vel: argparse.ArgumentParser) -> None:
    """Where the configurations come from and how they are run: ``--n``/``--configurations``,
    ``--seed``, ``--chunk-size``, ``--dtype``."""
    count = vel.add_mutually_exclusive_group()
    count.add_argument(
        "--n",
        type=_count,
        default=None,
        help=f"configurations to sample, at most {MAX_N:,} (default: {DEFAULT_N:,})",
    )
    count.add_argument(
        "--configurations",
        metavar="PATH",
        help="read q (and optionally qd) from a .npz or .csv file (- for standard input) "
        "instead of sampling; see below",
    )
    vel.add_argument(
        "--seed", type=_seed, default=0, help=f"random seed, 0 to {MAX_SEED:,} (default: 0)"
    )
    vel.add_argument(
        "--chunk-size",
        type=_chunk,
        default=CLI_CHUNK_SIZE,
        help=f"configurations per compiled call, at most {MAX_CHUNK:,} (default: %(default)s)",
    )
    _add_dtype_option(
        vel, "float precision (default: %(default)s; float64 enables jax_enable_x64 for this run)"
    )


def _add_velocities_output_options(vel: argparse.ArgumentParser) -> None:
    """Where the results go: ``--output``/``--no-output`` and ``--format``."""
    out = vel.add_mutually_exclusive_group()
    out.add_argument(
        "--output",
        metavar="PATH",
        help="output file, - for standard output (csv) (default: velocities_<robot>_<n>.<format> "
        "in the current directory)",
    )
    out.add_argument("--no-output", action="store_true", help="compute and summarise only")
    vel.add_argument(
        "--format",
        choices=OUTPUT_FORMATS,
        default=None,
        help="output format (default: from the --output suffix, else npz; see below)",
    )


def _add_velocities_kernel_options(vel: argparse.ArgumentParser) -> None:
    """What is computed per configuration (``--frame``, ``--reference``, ``--representation``,
    ``--qd-scale``, ``--singular-tol``) and ``--progress``."""
    _add_frame_option(vel)
    _add_reference_option(
        vel, "point and basis of J and the twist (default: %(default)s: frame origin, world axes)"
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
        help=(
            f"progress bar on stderr (default: on for N >= {PROGRESS_MIN_N:,} on a terminal); "
            'needs tqdm: pip install "jaxkin[progress]"'
        ),
    )


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
    except UsageError as e:
        return _usage_error(str(e))
    except jk.JaxkinError as e:
        return _usage_error(_cli_message(e))
    except KeyboardInterrupt:
        print("jaxkin: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # e.g. 'jaxkin robots | head': the reader left; stop quietly
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 141
    except OSError as e:  # writing the output: disk full, file too large, permission denied
        return _usage_error(f"{e.strerror or e}: {e.filename}" if e.filename else str(e))


# The library's advice names Python keywords; on the command line they are flags. Applied in
# order to the message of every jaxkin error the command line reports (NoDefaultFrameError has
# its own wording, from its attributes).
_PYTHON_TO_FLAGS = tuple(
    (re.compile(pattern), flags)
    for pattern, flags in (
        (r"\bleave (tip|base|frame)=None\b", r"leave out --\1"),
        (r"\b(tip|base|frame)=(?=[/)])", r"--\1"),  # "(tip=/base=)"
        (r"\b(tip|base|frame)=", r"--\1 "),
        (r"(?:load it with )?\bjk\.load_urdf\([^()]*\btrust=True\)", "pass --trust-xacro"),
        (r"\btrust=True\b", "--trust-xacro"),
        (r"\bjk\.robots\.(?:erd|mjcf)_names\(\)", "'jaxkin robots'"),
        (r"\bwith jk\.load_(?:mjcf|urdf)\(path\)", "by giving its path as ROBOT"),
    )
)


def _cli_message(error: Exception) -> str:
    """The message of a jaxkin error as the command line reports it: its keyword advice
    (``frame=``, ``tip=``, ``base=``, ``trust=True``) reworded as flags (``--frame`` ...)."""
    if isinstance(error, jk.NoDefaultFrameError):
        names = list(error.candidates)
        shown = names if len(names) <= 30 else [*names[:30], "..."]
        return (
            f"robot {error.robot!r} has no default frame: its moving joints branch, so no frame "
            f"is moved by all of them. Candidate end frames ({len(names)}): {shown}. Choose one "
            f"with --frame (e.g. --frame {names[0]}), or keep only the chain to it with --tip "
            "(URDF and MJCF robots)"
        )
    message = str(error)
    for pattern, flags in _PYTHON_TO_FLAGS:
        message = pattern.sub(flags, message)
    return message


def _frame_name(robot: jk.Robot, frame: int | str | None) -> str:
    """The name of the frame ``--frame`` gives (None: the default frame)."""
    try:
        return robot.frame_names[robot.frame_index(frame)]
    except jk.NoDefaultFrameError:
        raise
    except jk.JaxkinError as e:
        raise UsageError(f"--frame {frame}: {e}") from None


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
    urdf = jk.robots.erd_names()
    print()
    if urdf:
        print(f"# {len(urdf)} URDF robots of example-robot-data, loaded by name (e.g. {urdf[0]}):")
        for name in urdf:
            print(name)
    else:
        print("# URDF robots: install example-robot-data for more by name (erd/...)")
    mjcf = jk.robots.mjcf_names()
    print()
    if mjcf:
        print(f"# {len(mjcf)} MJCF robots of installed packages, loaded by name (e.g. {mjcf[0]}):")
        for name in mjcf:
            print(name)
    else:
        print("# MJCF robots: install dm-control or gymnasium-robotics for more by name (mjcf/...)")
    print("# any URDF file (or MJCF .xml file) also works as ROBOT: give its path")
    return 0


def load_robot(
    spec: str,
    dtype: str,
    tip: str | None = None,
    base: str | None = None,
    *,
    trust_xacro: bool = False,
):
    """The robot ``spec`` names, through :func:`jaxkin.robots.load`: a zoo name, an ``erd/...``
    or ``mjcf/...`` name, or the path of a URDF or MJCF file or, with ``trust_xacro``, of a
    ``.xacro`` file (expanded by the xacro package, which runs the file's code: refused without
    consent). Names win over files (:mod:`jaxkin.robots.files`).

    Returns ``(robot, label)``; ``label`` names output files. Every user mistake is a
    :class:`UsageError` or a :class:`jaxkin.JaxkinError` (a bad file's message names it).
    """
    zoo = jk.robots.names()
    if jk.robots.files.is_path(spec):
        path = pathlib.Path(spec)
        robot = _load_file(path, dtype, tip, base, trust_xacro)
        return _movable(robot, spec), pathlib.Path(path.name.removesuffix(XACRO_SUFFIX)).stem
    if spec not in zoo and not spec.startswith(NAME_PREFIXES):
        urdf = jk.robots.erd_names()
        more = f" or one of {len(urdf)} erd/... URDF robots" if urdf else ""
        raise UsageError(
            f"unknown robot {spec!r}; choose one of {', '.join(zoo)}{more}, or give a URDF or "
            "MJCF file path (see 'jaxkin robots')"
        )
    options = {k: v for k, v in (("tip", tip), ("base", base)) if v is not None}
    if options and spec in zoo:
        raise UsageError(
            f"--tip and --base apply to URDF robots; {spec!r} is a zoo model (use --frame)"
        )
    return _movable(jk.robots.load(spec, dtype=dtype, **options), spec), spec.replace("/", "_")


def _movable(robot, spec: str):
    """``robot``, or a :class:`UsageError` when it has no moving joint (nothing to compute) or
    has free, ball or planar joints (the command line samples q in a box)."""
    if robot.multi_dof_joints:
        kinds = sorted({robot.kinds[j] for j in robot.multi_dof_joints})
        raise UsageError(
            f"robot {spec!r} has {'/'.join(kinds)} joints (unit quaternions or (cos, sin) pairs "
            "in q); the command line handles robots with revolute and prismatic joints only. "
            "Use the Python API (jk.sample_configurations, jk.geometric_jacobian, ...), or "
            "--base below the joint"
        )
    if robot.dof == 0:
        raise UsageError(
            f"robot {spec!r} has no moving joint (dof 0): there is nothing to move; "
            "choose a robot (or --tip/--base) with a revolute or prismatic joint"
        )
    return robot


def _load_file(path: pathlib.Path, dtype: str, tip: str | None, base: str | None, trust: bool):
    """A robot from a URDF, MJCF or (``trust`` given) xacro file."""
    if not os.path.islink(path):  # a broken link or a loop: the loader says which
        if not path.exists():
            kind = "URDF or MJCF" if path.suffix.lower() == ".xml" else "URDF"
            raise UsageError(f"no such {kind} file: {path}")
        if not path.is_file():
            raise UsageError(f"{path} is not a file; give the path of a .urdf or MJCF .xml file")
    xacro = path.name.lower().endswith(XACRO_SUFFIX)
    if xacro and not trust:
        raise UsageError(
            f"{path} is a xacro file, and xacro files are programs (their ${{...}} expressions "
            "run Python, which nothing sandboxes): pass --trust-xacro only for files you trust, "
            f"or expand it yourself (xacro {path} > robot.urdf) and pass the .urdf"
        )
    try:
        return jk.robots.load(path, dtype=dtype, tip=tip, base=base, trust=trust)
    except OSError as e:
        raise UsageError(f"cannot read {path}: {e.strerror or e}") from None


# ---------------------------------------------------------------------- velocities
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


class _Summary:
    """The sink every chunk of results goes through, in row order: it passes the chunk on to
    the writer (if any) and keeps what the summary needs: the autodiff check's errors, whether
    any joint moves the frame, non-finite rows, near-singular counts and the twist norms (min,
    mean, max of all; median and p99 of every ``stride``-th row, so memory stays bounded)."""

    def __init__(self, n: int, tol: float, writer: ResultWriter | None) -> None:
        self.n, self.tol, self.writer, self.rows = n, tol, writer, 0
        self.errors: list[np.ndarray] = []
        self.moved, self.kin, self.rep, self.bad, self.first_bad = False, 0, 0, 0, None
        self.stride = max(-(-n // NORM_SAMPLE), 1)
        self.norms: dict[str, list[np.ndarray]] = {"v": [], "w": []}
        self.stats = {k: [math.inf, 0.0, -math.inf] for k in self.norms}  # min, sum, max

    def append(self, chunk: dict[str, np.ndarray]) -> None:
        chunk = dict(chunk)
        err = chunk.pop("jac_err", None)
        if err is not None:
            self.errors.append(np.asarray(err, dtype=np.float64))
        k = len(chunk["q"])
        bad = np.zeros(k, dtype=bool)
        for name, a in chunk.items():
            rows = ~np.isfinite(a.reshape(k, -1)).all(axis=1)
            if rows.any() and self.first_bad is None:
                self.first_bad = (self.rows + int(np.argmax(rows)), name)
            bad |= rows
        self.bad += int(np.count_nonzero(bad))
        self.moved = self.moved or bool(np.any(chunk["J"]))
        sigma = chunk["sigma"]
        self.kin += int(np.count_nonzero(~(sigma[:, -1] > self.tol * sigma[:, 0])))
        self.rep += int(np.count_nonzero(~(chunk["margin"] >= self.tol)))
        keep = (np.arange(self.rows, self.rows + k) % self.stride) == 0
        for key, part in (("v", chunk["twist"][:, :3]), ("w", chunk["twist"][:, 3:])):
            norms = np.linalg.norm(part.astype(np.float64, copy=False), axis=1)
            lo, total, hi = self.stats[key]
            self.stats[key] = [min(lo, norms.min()), total + norms.sum(), max(hi, norms.max())]
            self.norms[key].append(norms[keep].astype(np.float32))
        if self.writer is not None:
            self.writer.append(chunk)
        self.rows += k

    def jac_err(self) -> tuple[float, int]:
        errors = np.concatenate(self.errors)
        return float(np.max(errors)), len(errors)

    def norm_line(self, key: str, label: str) -> str:
        lo, total, hi = self.stats[key]
        med, p99 = np.percentile(np.concatenate(self.norms[key]), [50, 99])
        every = "" if self.stride == 1 else f" (median, p99 of every {self.stride}th)"
        return (
            f"{label:<16} min {lo:.4g}  mean {total / self.n:.4g}  median {med:.4g}  "
            f"p99 {p99:.4g}  max {hi:.4g}{every}"
        )


def cmd_velocities(args: argparse.Namespace) -> int:
    with _x64(args.dtype == "float64"):
        robot, label = load_robot(
            args.robot, args.dtype, args.tip, args.base, trust_xacro=args.trust_xacro
        )
        frame_name = _frame_name(robot, args.frame)
        q, qd, source = _velocity_inputs(args, robot)
        fmt, path = _output_choice(args, label, len(q))
        writer = None if path is None else _open_writer(args, robot, frame_name, path, fmt, len(q))
        with writer or contextlib.nullcontext():
            summary = _Summary(len(q), args.singular_tol, writer)
            stats = _run(args, robot, frame_name, q, qd, summary)
            failures = _failures(args, summary)
            if writer is not None and not failures:
                writer.commit()
        _report(args, robot, frame_name, q, source, summary, stats, path, failures)
    for message in failures:
        print(f"jaxkin: {message}", file=sys.stderr)
    return 1 if failures else 0


def _velocity_inputs(args: argparse.Namespace, robot: jk.Robot):
    """``(q, qd, (configurations path or None, qd read from it))``."""
    dtype = np.dtype(args.dtype)
    if args.configurations is None:
        return (
            *sample_rows(robot, args.n or DEFAULT_N, args.seed, args.qd_scale, dtype),
            (None, False),
        )
    try:
        q, qd = read_configurations(args.configurations, robot, dtype)
    except jk.JaxkinError as e:  # it names the file: reported as it is, no flags to translate
        raise UsageError(str(e)) from None
    if qd is None:
        return (
            q,
            sample_rows(robot, len(q), args.seed, args.qd_scale, dtype)[1],
            (args.configurations, False),
        )
    return q, qd, (args.configurations, True)


def _output_choice(args: argparse.Namespace, label: str, n: int) -> tuple[str | None, str | None]:
    """``(format, path)`` of the output, ``(None, None)`` for ``--no-output``."""
    if args.no_output:
        return None, None
    suffix = pathlib.Path(args.output or "").suffix.lower().lstrip(".")
    if args.output == "-":
        if args.format not in (None, "csv"):
            raise UsageError("--output - (standard output) takes --format csv only")
        return "csv", "-"
    if args.format is None:
        fmt = suffix if suffix in OUTPUT_FORMATS else "npz"
    elif suffix in OUTPUT_FORMATS and suffix != args.format:
        raise UsageError(
            f"--format {args.format} contradicts --output {args.output} (a .{suffix} name); "
            "change one of them"
        )
    else:
        fmt = args.format
    return fmt, args.output or f"velocities_{label}_{n}.{fmt}"


def _open_writer(args, robot: jk.Robot, frame: str, path: str, fmt: str, n: int) -> ResultWriter:
    """The output, opened before any work so that a bad path fails first."""
    kernel = _results_kernel(velocity_results, robot, frame, args.reference, args.representation)
    row = jax.ShapeDtypeStruct((robot.dof,), np.dtype(args.dtype))
    shapes = jax.eval_shape(kernel, row, row)
    fields = {k: (s.shape, s.dtype) for k, s in shapes.items()}
    meta = {
        "robot": robot.name,
        "joint_names": np.array(robot.joint_names),
        "frame": frame,
        "reference": args.reference,
        "representation": args.representation,
        "dtype": args.dtype,
        "seed": args.seed,
        "qd_scale": args.qd_scale,
        "singular_tol": args.singular_tol,
        "jaxkin_version": jk.__version__,
    }
    joints = list(robot.joint_names)
    columns = {
        "q": [f"q_{j}" for j in joints],
        "qd": [f"qd_{j}" for j in joints],
        "twist": ["vx", "vy", "vz", "wx", "wy", "wz"],
        "sigma": [f"sigma_{i + 1}" for i in range(fields["sigma"][0][0])],
        "margin": ["margin"],
    }
    comments = [f"jaxkin velocities: {k} = {v}" for k, v in meta.items() if k != "joint_names"]
    comments.append("twist [vx vy vz wx wy wz] = J @ qd; J and Ja are written by --format npz only")
    return ResultWriter(
        path, fields, n, format=fmt, meta=meta, columns=columns, comments=comments
    )  # fmt: skip


def _run(args, robot: jk.Robot, frame: str, q, qd, summary: _Summary) -> list[MapStats]:
    """The autodiff check on the first ``CHECK_ROWS`` configurations (their results written
    too), then the one-pass kernel on the rest; every chunk goes through ``summary``."""
    n, k = len(q), min(len(q), CHECK_ROWS)
    check = _results_kernel(
        velocity_results, robot, frame, args.reference, args.representation, check=True
    )
    _, first = chunked_map(
        check, q[:k], qd[:k], chunk_size=args.chunk_size, out=summary, return_stats=True
    )
    if not summary.moved:
        raise UsageError(
            f"frame {frame!r} of robot {robot.name!r} is not moved by any joint (every Jacobian "
            f"column is zero); choose another with --frame (frames: "
            f"{', '.join(robot.frame_names)}) or, for a URDF robot, --tip"
        )
    if k == n:
        return [first]
    show = n >= PROGRESS_MIN_N if args.progress is None else args.progress
    bar = ProgressBar(n - k, "velocities", unit="cfg", enabled=show, force=args.progress is True)
    fn = _results_kernel(velocity_results, robot, frame, args.reference, args.representation)
    rest = [a[k:] if isinstance(a, np.ndarray) else a.tail(k) for a in (q, qd)]
    _, stats = chunked_map(
        fn, *rest, chunk_size=args.chunk_size, progress=bar, out=summary, return_stats=True
    )
    return [first, stats]


@functools.lru_cache(maxsize=8)
def _results_kernel(make, robot: jk.Robot, frame: str, reference: str, representation: str,
                    check: bool = False):  # fmt: skip
    """``make(robot, frame, reference, representation)`` (``check=True`` passed on when set):
    the same function object for an equal robot and equal options, so that a later run in the
    same process (tests, a notebook calling :func:`main`) reuses its trace and compiled chunk
    kernel (:func:`jaxkin.batch.chunked_map` keeps them per function) instead of building them
    again. ``make`` is :func:`jaxkin.velocity.velocity_results`, passed in so that a replaced one
    is looked up when called."""
    if check:
        return make(robot, frame, reference, representation, check=True)
    return make(robot, frame, reference, representation)


def _failures(args: argparse.Namespace, summary: _Summary) -> list[str]:
    """One line per failed check: non-finite results, the autodiff check."""
    failures = []
    if summary.bad:
        row, name = summary.first_bad
        failures.append(
            f"{summary.bad:,} configuration(s) gave non-finite results (first: configuration "
            f"{row}, {name}); at a representation singularity (margin 0) choose another "
            "--representation; no output was written"
        )
    err, _ = summary.jac_err()
    if not err <= CHECK_TOL[args.dtype]:  # also for NaN
        failures.append("the hand-built and autodiff Jacobians disagree beyond tolerance")
    return failures


def _report(args, robot, frame, q, source, summary, stats, path, failures) -> None:
    """The summary, on stdout (on stderr when the results go to stdout)."""
    n, tol = len(q), args.singular_tol
    err, checked = summary.jac_err()
    check_tol = CHECK_TOL[args.dtype]
    pct = lambda k: 100.0 * k / n  # noqa: E731
    margin_name = {"rpy": "|cos(pitch)|", "zyz": "|sin(theta)|", "rotvec": "1 - |w|/(2 pi)"}
    run_seconds = sum(s.run_seconds for s in stats)
    main = stats[-1]
    lines = [
        f"robot            {_shown(robot.name)} ({robot.dof} dof: "
        f"{', '.join(map(_shown, robot.joint_names))})",
        f"frame            {frame}, reference {args.reference}, "
        f"representation {args.representation}",
        f"configurations   {_source_line(args, robot, q, source)}",
        f"dtype            {_dtype_note(args.dtype)}",
        f"chunks           {sum(s.n_chunks for s in stats)}: {checked:,} checked rows, then "
        f"{main.n_chunks if len(stats) > 1 else 0} x {main.chunk_size:,} "
        f"({sum(s.padding for s in stats):,} padding rows)",
        f"compile          {sum(s.compile_seconds for s in stats):.2f} s "
        "(once per kernel: checked, then one-pass)",
        f"throughput       {n / run_seconds if run_seconds else math.inf:,.0f} configurations/s "
        f"({run_seconds:.2f} s, compile excluded)",
        f"check            max |J_handbuilt - J_jacfwd| = {err:.3g} over the first {checked:,} "
        f"configurations  {'PASS' if err <= check_tol else 'FAIL'} (tol {check_tol:g})",
        f"near kinematic singularity       {summary.kin:,} ({pct(summary.kin):.3g}%): "
        f"sigma_min/sigma_max < {tol:g}",
        f"near representation singularity  {summary.rep:,} ({pct(summary.rep):.3g}%): "
        f"{margin_name[args.representation]} < {tol:g}",
        summary.norm_line("v", "|v|     [m/s]"),
        summary.norm_line("w", "|omega| [rad/s]"),
        f"output           {_output_line(path, failures)}",
    ]
    stream = sys.stderr if path == "-" else sys.stdout
    print("jaxkin velocities", file=stream)
    for line in lines:
        print(f"  {line}", file=stream)


def _dtype_note(dtype: str) -> str:
    """The summary's dtype line: the command line's float64 is not the library's default."""
    if dtype == "float64":
        return (
            "float64 (jax_enable_x64 turned on for this run; the library follows JAX's float32 "
            "default: jax.config.update('jax_enable_x64', True) for float64 in Python)"
        )
    return "float32 (--dtype float32, JAX's default; the command line's default is float64)"


def _output_line(path: str | None, failures: list[str]) -> str:
    if path is None:
        return "none (--no-output)"
    if path == "-":
        return "standard output (csv)"
    if failures:
        return f"none: {path} not written, a check failed"
    full = os.path.abspath(path)
    return f"{full} ({os.path.getsize(full) / 1e6:,.1f} MB)"


def _source_line(args: argparse.Namespace, robot: jk.Robot, q: Any, source) -> str:
    path, qd_from_file = source
    sampled_qd = (
        f"qd uniform in [-{args.qd_scale:g}, {args.qd_scale:g}] rad/s or m/s, seed {args.seed}"
    )
    if path is None:
        return f"{len(q):,} (seed {args.seed}, {sampled_qd.replace(f', seed {args.seed}', '')})"
    lo, hi = np.asarray(robot.lower), np.asarray(robot.upper)
    outside = int(np.count_nonzero(np.any((q < lo) | (q > hi), axis=1)))
    qd_text = "qd from the file" if qd_from_file else sampled_qd
    name = "standard input" if path == "-" else path
    return f"{len(q):,} from {name} ({qd_text}; {outside:,} outside the joint limits)"


# ---------------------------------------------------------------------- jacobian
def cmd_jacobian(args: argparse.Namespace) -> int:
    with _x64(args.dtype == "float64"):
        robot, _ = load_robot(
            args.robot, args.dtype, args.tip, args.base, trust_xacro=args.trust_xacro
        )
        q = _joint_values(args, robot)
        frame = _frame_name(robot, args.frame)
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
        sys.stdout.write(csv_record(["row", *robot.joint_names]))
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
    tip = (
        " (the tip)"
        if robot.has_default_frame and robot.frame_index(frame) == robot.tip_frame
        else ""
    )
    units = ["rad" if k == "revolute" else "m" for k in robot.joint_kinds]
    q_text = ", ".join(
        f"{_shown(n)}={v:g} {u}" for n, v, u in zip(robot.joint_names, q, units, strict=True)
    )
    return [
        f"robot  {_shown(robot.name)} ({robot.dof} joints), frame {_shown(frame)}{tip}",
        f"q      {q_text}",
        f"J      {what}",
    ]


def _shown(name: str) -> str:
    """A name as printed on the terminal: itself when every character prints, else its Python
    repr (a newline or an escape sequence in a model file's name cannot forge a line or move
    the cursor)."""
    return name if name.isprintable() else repr(name)


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
    names = [_shown(n) for n in robot.joint_names]
    width = max(max(map(len, names)), max(len(c) for r in cells for c in r))
    lw = max(len(s) for s in labels)
    lines = _jacobian_header(robot, frame, q, reference, representation, point)
    if representation is None:
        per = "per unit joint rate: a column is per rad/s (revolute joint) or per m/s (prismatic)"
    else:
        per = "derivatives: a column is per rad (revolute joint) or per m (prismatic)"
    lines.append(f"rows   {' '.join(rows)} ({per})")
    lines.append("")
    lines.append(" " * lw + "  " + " ".join(f"{n:>{width}}" for n in names))
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
