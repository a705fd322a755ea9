"""Mutation fuzzing over real URDFs: every mutant either loads to a model whose kinematics are
finite, or raises a jaxkin error (``jk.ModelError``); never anything else (no KeyError,
IndexError, RecursionError, TypeError, numpy warning, hang).

Base files: example-robot-data's Panda (tree, mimic), UR5 and Kinova (continuous joints), the
iiwa fixture and ``tests/data/tree_mimic.urdf`` (mimic chain, branches, fixed frames). Each mutant
applies one operator, chosen with a fixed seed (``SEED``): delete or duplicate a kinematic
element (joint, link, origin, axis, limit, parent, child, mimic), replace a number in an
attribute by nan / inf / -inf / 1e308 / 1e999 / 1e-320 / "" / text / a wrong count / a xacro
expression, replace a name (empty, unknown, another existing one), swap a joint's type (every
URDF type, "floating", "planar" and nonsense), re-parent a joint to a random link (cycles,
self-loops, two parents), point a mimic anywhere, add a DOCTYPE, or truncate the file.
``MUTANTS_PER_FILE`` mutants per file run in the default suite (HYPOTHESIS-style fixed seed;
``JAXKIN_FUZZ_MUTANTS`` raises it).

A loaded mutant is checked: every float leaf of the model finite (limits may be infinite, never
NaN, lower <= upper), and ``fk_all`` plus the geometric Jacobian of every frame's last link at a
configuration inside the limits finite. A mutant that urdfdom loads too (a duplicated ``<axis>``,
a limit that ends up below the other) may load with a ``URDFWarning``, the only warning allowed.

No explosion: a loaded model has no more joints than the mutant has ``<joint`` elements. No hang:
a watchdog (:data:`HANG_SECONDS`, far above what any mutant takes on a busy machine, so it never
fires on load alone) fails the test naming the mutant instead of letting it run for ever; times
are never asserted. The kinematics of a loaded mutant (a robot used once) run op by op
(``jax.disable_jit()``): nothing is compiled per mutant.
"""

from __future__ import annotations

import collections
import contextlib
import os
import re
import signal
import threading
import warnings

import jax
import numpy as np
import pytest
from _urdf_support import DATA, erd_root

import jaxkin as jk
from jaxkin.urdf import URDFWarning, load_urdf

SEED = 1234
MUTANTS_PER_FILE = int(os.environ.get("JAXKIN_FUZZ_MUTANTS", "60"))
HANG_SECONDS = 120

BASES = {
    "panda": ("erd", "panda_description/urdf/panda.urdf"),
    "ur5": ("erd", "ur_description/urdf/ur5_robot.urdf"),
    "kinova": ("erd", "kinova_description/robots/kinova.urdf"),
    "iiwa": ("data", "kuka_iiwa14.urdf"),
    "tree_mimic": ("data", "tree_mimic.urdf"),
}

KIN_TAGS = ("joint", "link", "origin", "axis", "limit", "parent", "child", "mimic")
NUMBERS = [
    "nan",
    "NaN",
    "inf",
    "-inf",
    "1e308",
    "-1e308",
    "1e999",
    "1e-320",
    "",
    "abc",
    "0x10",
    "1 2",
    "1 2 3 4",
    "${pi/2}",
    "0",
    "-0",
    "1e6",
    "1e7",
]
TYPES = [
    "revolute",
    "continuous",
    "prismatic",
    "fixed",
    "floating",
    "planar",
    "spherical",
    "",
    "REVOLUTE",
]


def _source(name: str) -> str:
    kind, rel = BASES[name]
    if kind == "erd":
        root = erd_root()
        if root is None:
            pytest.skip("example-robot-data is not installed (test extra)")
        return (root / rel).read_text()
    return (DATA / rel).read_text()


_TAG = re.compile(r"<(" + "|".join(KIN_TAGS) + r")\b[^>]*?(/>|>)", re.S)
_ATTR = re.compile(r'(\w+)="([^"]*)"')


def _elements(text: str):
    """(tag, start, end) of every kinematic element, the whole element for <joint>/<link>."""
    out = []
    for m in _TAG.finditer(text):
        tag, start = m.group(1), m.start()
        if m.group(2) == "/>":
            out.append((tag, start, m.end()))
            continue
        close = text.find(f"</{tag}>", m.end())
        if close >= 0:
            out.append((tag, start, close + len(tag) + 3))
    return out


def _attributes(text: str):
    """(tag, attribute, value start, value end) inside kinematic tags."""
    out = []
    for m in _TAG.finditer(text):
        for a in _ATTR.finditer(m.group(0)):
            out.append((m.group(1), a.group(1), m.start() + a.start(2), m.start() + a.end(2)))
    return out


def _names(text: str, tag: str) -> list[str]:
    return re.findall(rf'<{tag}\s+name="([^"]*)"', text)


def mutate(text: str, rng: np.random.Generator) -> tuple[str, str]:
    """One random mutation of ``text``: (mutant, description)."""
    links, joints = _names(text, "link"), _names(text, "joint")
    op = rng.choice(
        [
            "delete",
            "duplicate",
            "number",
            "name",
            "type",
            "reparent",
            "mimic",
            "doctype",
            "truncate",
        ],
        p=[0.14, 0.1, 0.3, 0.1, 0.1, 0.1, 0.08, 0.03, 0.05],
    )
    if op in ("delete", "duplicate"):
        tag, a, b = _elements(text)[rng.integers(len(_elements(text)))]
        piece = text[a:b]
        new = text[:a] + text[b:] if op == "delete" else text[:b] + piece + text[b:]
        return new, f"{op} <{tag}> at offset {a}"
    if op in ("number", "name"):
        attrs = _attributes(text)
        if op == "number":
            attrs = [
                x for x in attrs if x[1] in ("xyz", "rpy", "lower", "upper", "multiplier", "offset")
            ]
        else:
            attrs = [x for x in attrs if x[1] in ("name", "link", "joint")]
        tag, attr, a, b = attrs[rng.integers(len(attrs))]
        old = text[a:b]
        if op == "number":
            tokens = old.split() or ["0"]
            k = int(rng.integers(len(tokens)))
            tokens[k] = str(rng.choice(NUMBERS))
            value = " ".join(tokens)
        else:
            value = str(rng.choice(["", "ghost", *links[:20], *joints[:20]]))
        return text[:a] + value + text[b:], f"<{tag}> {attr}={old!r} -> {value!r}"
    if op == "type":
        spots = [m for m in re.finditer(r'(<joint\s+name="[^"]*"\s+type=")([^"]*)"', text)]
        if not spots:
            spots = [m for m in re.finditer(r'(<joint\s[^>]*?type=")([^"]*)"', text)]
        m = spots[rng.integers(len(spots))]
        value = str(rng.choice(TYPES))
        return text[: m.start(2)] + value + text[m.end(2) :], f"type {m.group(2)} -> {value}"
    if op == "reparent":
        spots = list(re.finditer(r'<parent\s+link="([^"]*)"', text))
        m = spots[rng.integers(len(spots))]
        value = str(rng.choice(links))
        return text[: m.start(1)] + value + text[m.end(1) :], f"parent {m.group(1)} -> {value}"
    if op == "mimic":
        closes = [m.start() for m in re.finditer(r"</joint>", text)]
        at = closes[rng.integers(len(closes))]
        leader = str(rng.choice([*joints, "nowhere"]))
        tag = f'<mimic joint="{leader}" multiplier="{rng.normal():.3f}"/>'
        return text[:at] + tag + text[at:], f"add {tag}"
    if op == "doctype":
        at = text.find("<robot")
        return text[:at] + '<!DOCTYPE robot [<!ENTITY x "y">]>\n' + text[at:], "add DOCTYPE"
    cut = int(rng.integers(len(text)))
    return text[:cut], f"truncate at {cut}"


class MutantHang(BaseException):
    """Raised by the watchdog (a BaseException, so that no ``except Exception`` swallows it)."""


@contextlib.contextmanager
def _watchdog(seconds: float, what: str):
    """Raise :class:`MutantHang` naming ``what`` if the block runs ``seconds`` of wall time (a
    hang, not a slow machine); a no-op where SIGALRM is not available (Windows, a thread)."""
    main = threading.current_thread() is threading.main_thread()
    if not (main and hasattr(signal, "setitimer")):
        yield
        return

    def fire(signum, frame):
        raise MutantHang(f"{what} still running after {seconds} s: a hang")

    previous = signal.signal(signal.SIGALRM, fire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def _check_loaded(robot: jk.Robot, rng: np.random.Generator, what: str) -> None:
    for leaf in (
        robot.params["xyz"],
        robot.params["rpy"],
        robot.axis,
        robot.offset,
        robot.multiplier,
        robot.base,
        robot.tool,
    ):
        assert np.all(np.isfinite(np.asarray(leaf))), what
    lo, hi = np.asarray(robot.lower), np.asarray(robot.upper)
    assert not np.any(np.isnan(lo)) and not np.any(np.isnan(hi)) and np.all(lo <= hi), what
    q = np.clip(rng.uniform(-1.0, 1.0, robot.nq), lo, hi)
    Ts = np.asarray(jk.fk_all(robot, q))
    assert np.all(np.isfinite(Ts)), what
    # the last frame (a mutant may branch: then there is no default frame)
    J = np.asarray(jk.geometric_jacobian(robot, q, frame=-1, reference="world"))
    assert np.all(np.isfinite(J)), what


@pytest.mark.parametrize("base", list(BASES))
def test_mutants_load_finite_or_raise_model_error(base):
    text = _source(base)
    rng = np.random.default_rng([SEED, list(BASES).index(base)])
    outcomes = collections.Counter()
    for i in range(MUTANTS_PER_FILE):
        mutant, what = mutate(text, rng)
        what = f"{base} mutant {i}: {what}"
        with _watchdog(HANG_SECONDS, what):
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", URDFWarning)  # urdfdom loads these too
                    robot = load_urdf(mutant, dtype=np.float64)
            except jk.ModelError as e:
                message = str(e)
                assert message.startswith("<string>") and len(message) > 20, (what, message)
                outcomes["ModelError"] += 1
            except Exception as e:  # anything else is a bug
                pytest.fail(f"{what} raised {type(e).__name__}: {e}")
            else:
                assert robot.n_joints <= mutant.count("<joint"), what  # no explosion
                with jax.disable_jit():  # a robot used once: op by op, nothing compiled for it
                    _check_loaded(robot, rng, what)
                outcomes["loaded"] += 1
    # Both outcomes occur (the operators are neither all harmless nor all fatal).
    assert outcomes["ModelError"] >= MUTANTS_PER_FILE // 5, outcomes
    assert outcomes["loaded"] >= MUTANTS_PER_FILE // 10, outcomes
