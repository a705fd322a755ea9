"""Batched Jacobian benchmark: jaxkin against Pinocchio (from Python), Niryo One and Panda.

For each robot, Jacobian kind (geometric at the tip, world-aligned; analytical in rpy with its
margin), dtype (float32, float64) and batch size N:

* compile time, apart: ``jit(vmap(f)).lower(q)`` (trace + lower) and ``.compile()``;
* steady state: warm-up, then ``repeats`` samples, each a loop of calls with ``block_until_ready``
  after every call (a sample lasts at least ``target_s``); the median is reported;
* Pinocchio, one Python call per configuration (``computeFrameJacobian(..., LOCAL_WORLD_ALIGNED)``;
  for the analytical rows also ``matrixToRpy`` and ``computeRpyJacobianInverse``), timed over
  ``pin_configs`` configurations *interleaved* with the jaxkin samples of the same row, so both see
  the same machine load; the row's ratio is jaxkin's Jacobians/s over Pinocchio's;
* a correctness check per row: jaxkin's first configurations against Pinocchio's Jacobians.

Usage: ``python3 -m bench [--quick] [--out PATH] [--no-plot]``. Writes ``bench/results/latest.json``
(``quick.json`` with ``--quick``) and prints a markdown table. Needs ``pin``; the Panda URDF comes
from the installed ``example-robot-data`` (offline).
"""

from __future__ import annotations

import argparse
import datetime
import gc
import json
import math
import os
import platform
import re
import site
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

import jaxkin as jk

RESULTS_DIR = Path(__file__).resolve().parent / "results"

FULL = dict(ns=(1, 100, 10_000, 100_000), repeats=7, target_s=0.05, pin_configs=20_000)
QUICK = dict(ns=(1, 10_000), repeats=2, target_s=0.01, pin_configs=2_000)
CHECK_CONFIGS = 32  # configurations of each row compared with Pinocchio

# ---------------------------------------------------------------------------- robots

# Franka Emika Panda, modified DH (Craig), from Franka's published table; the flange's d = 0.107 is
# folded into the last row (Tz commutes with the joint's Rz, so the last frame is the flange).
PANDA_MDH = dict(
    a=(0.0, 0.0, 0.0, 0.0825, -0.0825, 0.0, 0.088),
    d=(0.333, 0.0, 0.316, 0.0, 0.384, 0.0, 0.107),
    alpha=(0.0, -math.pi / 2, math.pi / 2, math.pi / 2, -math.pi / 2, math.pi / 2, math.pi / 2),
    lower=(-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973),
    upper=(2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973),
)


def panda_jaxkin(dtype) -> tuple[jk.Robot, str]:
    """The zoo Panda when the zoo has one, else one built here from the modified-DH table."""
    if "panda" in jk.robots.names():
        return jk.robots.load("panda", dtype=dtype), "jk.robots.load('panda')"
    rows = [
        dict(
            a=PANDA_MDH["a"][i],
            d=PANDA_MDH["d"][i],
            alpha=PANDA_MDH["alpha"][i],
            theta=0.0,
            joint="revolute",
            lower=PANDA_MDH["lower"][i],
            upper=PANDA_MDH["upper"][i],
            name=f"panda_joint{i + 1}",
        )
        for i in range(7)
    ]
    robot = jk.Robot.from_dh(rows, convention="modified", name="panda", dtype=dtype)
    return robot, "jk.Robot.from_dh(Franka modified DH, built in bench)"


def niryo_jaxkin(dtype) -> tuple[jk.Robot, str]:
    return jk.robots.load("niryo_one", dtype=dtype), "jk.robots.load('niryo_one')"


def _find_example_robot_data_urdf(rel: str) -> Path:
    """The path of an example-robot-data file, offline (the cmeel wheel has no Python module)."""
    try:  # older wheels ship a Python loader
        import example_robot_data  # type: ignore[import-not-found]

        return Path(example_robot_data.getModelPath(rel)) / rel
    except Exception:
        pass
    roots = [*site.getsitepackages(), site.getusersitepackages(), *sys.path]
    for root in roots:
        p = Path(root) / "cmeel.prefix" / "share" / "example-robot-data" / "robots" / rel
        if p.is_file():
            return p
    raise FileNotFoundError(
        f"example-robot-data's {rel} was not found under any site-packages cmeel.prefix; "
        "install it with `pip install example-robot-data`."
    )


def pin_panda():
    """Pinocchio Panda from example-robot-data's URDF, fingers locked (7 DOF)."""
    import pinocchio as pin

    path = _find_example_robot_data_urdf("panda_description/urdf/panda.urdf")
    full = pin.buildModelFromUrdf(str(path))
    lock = [
        full.getJointId(n)
        for n in ("panda_finger_joint1", "panda_finger_joint2")
        if full.existJointName(n)
    ]
    model = pin.buildReducedModel(full, lock, pin.neutral(full)) if lock else full
    return model, f"example-robot-data {path.name} (fingers locked)"


def urdf_from_placement_robot(robot: jk.Robot) -> str:
    """A URDF string with exactly the numbers of a jaxkin 'placement' (URDF-style) robot."""
    if robot.parameterisation != "placement":
        raise ValueError(f"expected a placement robot, got {robot.parameterisation!r}")
    xyz = np.asarray(robot.params["xyz"], dtype=np.float64)
    rpy = np.asarray(robot.params["rpy"], dtype=np.float64)
    axis = np.asarray(robot.axis, dtype=np.float64)
    lower = np.asarray(robot.lower, dtype=np.float64)
    upper = np.asarray(robot.upper, dtype=np.float64)
    links = robot.frame_names
    out = [f'<robot name="{robot.name}">']
    out += [f'  <link name="{name}"/>' for name in links[: robot.n_joints + 1]]

    def vec(v):
        return " ".join(repr(float(x)) for x in v)

    topology = zip(robot.kinds, robot.parents, robot.q_index, strict=True)
    for j, (kind, parent, qi) in enumerate(topology):
        name = robot.joint_names[qi] if qi >= 0 else f"fixed_{j}"
        out.append(f'  <joint name="{name}" type="{kind}">')
        out.append(f'    <parent link="{links[parent]}"/><child link="{links[j + 1]}"/>')
        out.append(f'    <origin xyz="{vec(xyz[j])}" rpy="{vec(rpy[j])}"/>')
        if kind != "fixed":
            out.append(f'    <axis xyz="{vec(axis[j])}"/>')
            out.append(
                f'    <limit lower="{float(lower[qi])!r}" upper="{float(upper[qi])!r}" '
                'effort="1" velocity="1"/>'
            )
        out.append("  </joint>")
    out.append("</robot>")
    return "\n".join(out)


def pin_niryo(robot64: jk.Robot):
    import pinocchio as pin

    model = pin.buildModelFromXML(urdf_from_placement_robot(robot64))
    return model, "URDF string generated in bench from jaxkin's niryo_one numbers"


def _match_tip_frame(model, robot64: jk.Robot, qs: np.ndarray) -> int:
    """The Pinocchio frame whose pose equals jaxkin's tip pose at a few configurations.

    Joint and body frames often coincide; a body (link) frame is preferred.
    """
    import pinocchio as pin

    data = model.createData()
    T_jk = [np.asarray(jk.fk(robot64, q)) for q in qs]
    errors = []
    for fid in range(model.nframes):
        err = 0.0
        for q, T in zip(qs, T_jk, strict=True):
            pin.framesForwardKinematics(model, data, q)
            err = max(err, float(np.abs(data.oMf[fid].homogeneous - T).max()))
        errors.append(err)
    matches = [fid for fid, err in enumerate(errors) if err < 1e-9]
    if not matches:
        best = int(np.argmin(errors))
        raise RuntimeError(
            f"no Pinocchio frame matches jaxkin's tip pose of {robot64.name!r} "
            f"(closest: {model.frames[best].name}, error {errors[best]:.3g}); the models differ."
        )
    bodies = [fid for fid in matches if model.frames[fid].type == pin.FrameType.BODY]
    return (bodies or matches)[-1]


# ---------------------------------------------------------------------------- Pinocchio loops


def pin_geometric_loop(model, data, fid, qs_list):
    import pinocchio as pin

    jac, lwa = pin.computeFrameJacobian, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
    for q in qs_list:
        jac(model, data, q, fid, lwa)


def pin_geometric_one(model, data, fid, q):
    import pinocchio as pin

    return pin.computeFrameJacobian(model, data, q, fid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)


def pin_analytical_one(model, data, fid, q):
    """Pinocchio's rpy analytical Jacobian [dp; drpy]/dq for one configuration."""
    import pinocchio as pin

    J = pin.computeFrameJacobian(model, data, q, fid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
    rpy = pin.rpy.matrixToRpy(data.oMf[fid].rotation)
    J[3:] = pin.rpy.computeRpyJacobianInverse(rpy, pin.ReferenceFrame.WORLD) @ J[3:]
    return J


def pin_analytical_loop(model, data, fid, qs_list):
    import pinocchio as pin

    jac, lwa, world = (
        pin.computeFrameJacobian,
        pin.ReferenceFrame.LOCAL_WORLD_ALIGNED,
        pin.ReferenceFrame.WORLD,
    )
    to_rpy, rpy_jinv = pin.rpy.matrixToRpy, pin.rpy.computeRpyJacobianInverse
    oMf = data.oMf
    for q in qs_list:
        J = jac(model, data, q, fid, lwa)
        J[3:] = rpy_jinv(to_rpy(oMf[fid].rotation), world) @ J[3:]


# ---------------------------------------------------------------------------- measurement


@dataclass
class Case:
    robot: str
    kind: str  # "geometric" or "analytical"
    dtype: str
    n: int
    source: str = ""
    lower_s: float = math.nan
    compile_s: float = math.nan
    first_call_s: float = math.nan
    hlo: dict[str, int] = field(default_factory=dict)
    calls_per_sample: int = 0
    samples_s: list[float] = field(default_factory=list)  # seconds per call (N Jacobians)
    pin_samples_s: list[float] = field(default_factory=list)  # seconds per Jacobian
    max_abs_err_vs_pin: float = math.nan

    @property
    def per_jac_s(self) -> float:
        return float(np.median(self.samples_s)) / self.n

    @property
    def pin_per_jac_s(self) -> float:
        return float(np.median(self.pin_samples_s))

    def summary(self) -> dict[str, Any]:
        d = dict(self.__dict__)
        d.update(
            jac_per_s=1.0 / self.per_jac_s,
            us_per_jac=self.per_jac_s * 1e6,
            pin_jac_per_s=1.0 / self.pin_per_jac_s,
            pin_us_per_jac=self.pin_per_jac_s * 1e6,
            ratio_vs_pin=self.pin_per_jac_s / self.per_jac_s,
        )
        return d


def _hlo_stats(compiled) -> dict[str, int]:
    """Counts in the optimised HLO's ENTRY computation: operations (parameters, constants and
    bitcasts left out), loop fusions, and unfused ``dot`` ops (each a separate small matmul)."""
    try:
        text = compiled.as_text()
    except Exception:
        return {}
    m = re.search(r"^ENTRY .*?\{\n(.*?)^\}", text, flags=re.S | re.M)
    if not m:
        return {}
    body = [ln for ln in m.group(1).splitlines() if " = " in ln]
    ops = [ln for ln in body if not re.search(r"= \S+ (parameter|constant|bitcast)\(", ln)]
    return dict(
        ops=len(ops),
        fusions=sum(bool(re.search(r"= \S+ fusion\(", ln)) for ln in ops),
        dots=sum(bool(re.search(r"= \S+ dot\(", ln)) for ln in ops),
    )


def dispatch_floor_s(dof: int, repeats: int, target_s: float) -> float:
    """Seconds per call of a trivial jitted function on a (1, dof) input (the dispatch floor)."""
    fn = jax.jit(lambda q: q + 1.0)
    q = jnp.zeros((1, dof))
    jax.block_until_ready(fn(q))
    inner = 200
    samples = []
    for _ in range(max(repeats, 3)):
        t = time.perf_counter()
        for _ in range(inner):
            jax.block_until_ready(fn(q))
        samples.append((time.perf_counter() - t) / inner)
        inner = max(inner, math.ceil(target_s / max(samples[-1], 1e-7)))
    return float(np.median(samples))


def _sample_q(robot: jk.Robot, n: int, rng: np.random.Generator) -> np.ndarray:
    lo = np.asarray(robot.lower, dtype=np.float64)
    hi = np.asarray(robot.upper, dtype=np.float64)
    lo = np.where(np.isfinite(lo), lo, -np.pi)
    hi = np.where(np.isfinite(hi), hi, np.pi)
    return rng.uniform(lo, hi, size=(n, robot.dof))


def _kernel(robot: jk.Robot, kind: str):
    if kind == "geometric":
        return jax.jit(jax.vmap(lambda q: jk.geometric_jacobian(robot, q)))
    return jax.jit(jax.vmap(lambda q: jk.analytical_jacobian(robot, q, "rpy", return_margin=True)))


def run_case(case, fn, q, q64, pin_ctx, cfg) -> None:
    model, data, fid = pin_ctx
    loop = pin_geometric_loop if case.kind == "geometric" else pin_analytical_loop
    pin_qs = cfg["pin_qs"]

    t0 = time.perf_counter()
    lowered = fn.lower(q)
    t1 = time.perf_counter()
    compiled = lowered.compile()
    t2 = time.perf_counter()
    out = jax.block_until_ready(fn(q))  # served from jit's cache (same executable)
    t3 = time.perf_counter()
    case.lower_s, case.compile_s, case.first_call_s = t1 - t0, t2 - t1, t3 - t2
    case.hlo = _hlo_stats(compiled)

    # correctness against Pinocchio on the first configurations of this very batch
    J = np.asarray(out if case.kind == "geometric" else out[0], dtype=np.float64)
    one = pin_geometric_one if case.kind == "geometric" else pin_analytical_one
    k = min(case.n, CHECK_CONFIGS)
    case.max_abs_err_vs_pin = float(
        max(np.abs(J[i] - one(model, data, fid, q64[i])).max() for i in range(k))
    )

    # warm up and calibrate the number of calls per sample
    for _ in range(2):
        jax.block_until_ready(fn(q))
    t = time.perf_counter()
    jax.block_until_ready(fn(q))
    t_call = time.perf_counter() - t
    inner = max(1, math.ceil(cfg["target_s"] / max(t_call, 1e-7)))
    case.calls_per_sample = inner

    gc_was_enabled = gc.isenabled()
    gc.disable()
    try:
        for _ in range(cfg["repeats"]):
            t = time.perf_counter()
            for _ in range(inner):
                jax.block_until_ready(fn(q))
            case.samples_s.append((time.perf_counter() - t) / inner)
            t = time.perf_counter()
            loop(model, data, fid, pin_qs)
            case.pin_samples_s.append((time.perf_counter() - t) / len(pin_qs))
    finally:
        if gc_was_enabled:
            gc.enable()


# ---------------------------------------------------------------------------- environment


def machine_info() -> dict[str, Any]:
    import jaxlib
    import pinocchio as pin

    cpu_models, mem, mhz, flags = [], None, None, set()
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                key, _, value = line.partition(":")
                key, value = key.strip(), value.strip()
                if key == "model name":
                    cpu_models.append(value)
                elif key == "cpu MHz" and mhz is None:
                    mhz = value
                elif key == "flags" and not flags:
                    flags = set(value.split())
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemTotal"):
                    mem = line.split(":", 1)[1].strip()
    except OSError:
        pass
    try:
        affinity = len(os.sched_getaffinity(0))
    except AttributeError:
        affinity = None
    return dict(
        date_utc=datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        cpu_model=sorted(set(cpu_models)),
        cpu_mhz=mhz,
        simd=[x for x in ("sse4_2", "avx", "avx2", "fma", "avx512f") if x in flags],
        logical_cpus=os.cpu_count(),
        cpus_usable=affinity,
        mem_total=mem,
        platform=platform.platform(),
        python=platform.python_version(),
        jax=jax.__version__,
        jaxlib=jaxlib.__version__,
        numpy=np.__version__,
        pinocchio=pin.__version__,
        jaxkin=getattr(jk, "__version__", "?"),
        jax_devices=[str(d) for d in jax.devices()],
        xla_flags=os.environ.get("XLA_FLAGS", ""),
    )


# ---------------------------------------------------------------------------- reporting


def _fmt_rate(x: float) -> str:
    if x >= 1e6:
        return f"{x / 1e6:.2f} M"
    if x >= 1e3:
        return f"{x / 1e3:.1f} k"
    return f"{x:.0f}"


def _fmt_us(x: float) -> str:
    return f"{x:.3g}" if x < 100 else f"{x:.0f}"


def markdown_table(rows: list[dict[str, Any]]) -> str:
    head = (
        "| robot | Jacobian | dtype | N | compile s (trace+lower / XLA) | Jacobians/s "
        "| us/Jacobian (min-max) | Pinocchio/s (float64) | jaxkin / Pinocchio "
        "| max abs diff vs Pinocchio |\n"
        "|---|---|---|---:|---:|---:|---:|---:|---:|---:|"
    )
    lines = [head]
    for r in rows:
        lines.append(
            f"| {r['robot']} | {r['kind']} | {r['dtype']} | {r['n']:,} "
            f"| {r['lower_s']:.2f} / {r['compile_s']:.2f} "
            f"| {_fmt_rate(r['jac_per_s'])} | {_fmt_us(r['us_per_jac'])} "
            f"({_fmt_us(min(r['samples_s']) * 1e6 / r['n'])}-"
            f"{_fmt_us(max(r['samples_s']) * 1e6 / r['n'])}) "
            f"| {_fmt_rate(r['pin_jac_per_s'])} | {r['ratio_vs_pin']:.2f}x "
            f"| {r['max_abs_err_vs_pin']:.1e} |"
        )
    return "\n".join(lines)


def plot(rows: list[dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    robots = sorted({r["robot"] for r in rows})
    fig, axes = plt.subplots(1, len(robots), figsize=(5.5 * len(robots), 4), squeeze=False)
    for ax, name in zip(axes[0], robots, strict=True):
        for kind, color in (("geometric", "C0"), ("analytical", "C1")):
            for dtype, style in (("float64", "-o"), ("float32", "--s")):
                sel = [
                    r for r in rows if (r["robot"], r["kind"], r["dtype"]) == (name, kind, dtype)
                ]
                if sel:
                    ax.loglog(
                        [r["n"] for r in sel],
                        [r["us_per_jac"] for r in sel],
                        style,
                        color=color,
                        label=f"jaxkin {kind} {dtype}",
                    )
            pin_sel = [r["pin_us_per_jac"] for r in rows if (r["robot"], r["kind"]) == (name, kind)]
            if pin_sel:
                ax.axhline(
                    float(np.median(pin_sel)),
                    color=color,
                    linestyle=":",
                    label=f"Pinocchio {kind} (Python loop)",
                )
        ax.set_title(name)
        ax.set_xlabel("batch size N")
        ax.set_ylabel("microseconds per Jacobian (median)")
        ax.grid(True, which="both", alpha=0.3)
    axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ---------------------------------------------------------------------------- main


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python3 -m bench", description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="smoke run: N <= 10k, 2 repeats")
    parser.add_argument("--out", type=Path, default=None, help="where to write the JSON results")
    parser.add_argument("--no-plot", action="store_true", help="skip the PNG plot")
    args = parser.parse_args(argv)

    # A bench process may change the global JAX configuration (jaxkin itself never does).
    jax.config.update("jax_enable_x64", True)

    cfg = dict(QUICK if args.quick else FULL)
    out_path = args.out or RESULTS_DIR / ("quick.json" if args.quick else "latest.json")
    t_start = time.perf_counter()
    load_before = os.getloadavg()
    floor = dispatch_floor_s(6, cfg["repeats"], cfg["target_s"])

    rng = np.random.default_rng(20240607)
    builders = {"niryo_one": niryo_jaxkin, "panda": panda_jaxkin}
    pin_builders = {"niryo_one": pin_niryo, "panda": lambda _r: pin_panda()}
    rows, sources = [], {}
    for name, build in builders.items():
        robot64, src = build(np.float64)
        robot32, _ = build(np.float32)
        model, pin_src = pin_builders[name](robot64)
        data = model.createData()
        fid = _match_tip_frame(model, robot64, _sample_q(robot64, 3, rng))
        sources[name] = dict(
            jaxkin=src,
            pinocchio=pin_src,
            pinocchio_frame=model.frames[fid].name,
            dof=robot64.dof,
            parameterisation=robot64.parameterisation,
        )
        pin_qs = [np.ascontiguousarray(q) for q in _sample_q(robot64, cfg["pin_configs"], rng)]
        run_cfg = dict(cfg, pin_qs=pin_qs)
        q_pool = _sample_q(robot64, max(cfg["ns"]), rng)
        for kind in ("geometric", "analytical"):
            for dtype, robot in (("float32", robot32), ("float64", robot64)):
                fn = _kernel(robot, kind)
                for n in cfg["ns"]:
                    q64 = q_pool[:n]
                    q = jnp.asarray(q64.astype(dtype))
                    case = Case(robot=name, kind=kind, dtype=dtype, n=n, source=src)
                    run_case(case, fn, q, q64, (model, data, fid), run_cfg)
                    rows.append(case.summary())
                    r = rows[-1]
                    print(
                        f"  {name:9s} {kind:10s} {dtype} N={n:>7,}: compile "
                        f"{case.lower_s + case.compile_s:5.2f} s, {r['us_per_jac']:8.3g} us/J, "
                        f"Pinocchio {r['pin_us_per_jac']:.3g} us/J, "
                        f"ratio {r['ratio_vs_pin']:.2f}x",
                        file=sys.stderr,
                        flush=True,
                    )
                del fn
    elapsed = time.perf_counter() - t_start
    load_after = os.getloadavg()

    result = dict(
        benchmark="batched Jacobians, jaxkin vs Pinocchio (Python, one call per configuration)",
        mode="quick" if args.quick else "full",
        config={k: v for k, v in cfg.items()},
        machine=machine_info(),
        load_average_1_5_15min=dict(before=load_before, after=load_after),
        dispatch_floor_us=floor * 1e6,
        robots=sources,
        elapsed_s=elapsed,
        rows=rows,
    )
    out_path.parent.mkdir(parents=True, exist_ok=True)
    out_path.write_text(json.dumps(result, indent=1, default=float) + "\n")
    if not args.no_plot and not args.quick:
        plot(rows, out_path.with_suffix(".png"))

    m = result["machine"]
    print(
        f"\n{m['date_utc']}  {', '.join(m['cpu_model'])}, {m['cpus_usable']} usable CPUs; "
        f"python {m['python']}, jax {m['jax']}, jaxlib {m['jaxlib']}, numpy {m['numpy']}, "
        f"pin {m['pinocchio']}; {result['mode']} run in {elapsed:.0f} s -> {out_path}\n"
        f"load average (1 min) {load_before[0]:.2f} before, {load_after[0]:.2f} after; "
        f"dispatch floor (trivial jitted call) {floor * 1e6:.1f} us\n"
    )
    for name, s in sources.items():
        print(f"- {name}: jaxkin {s['jaxkin']}; Pinocchio {s['pinocchio']}, {s['pinocchio_frame']}")
    print()
    print(markdown_table(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
