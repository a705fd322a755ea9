"""xacro files are programs: ``jk.load_urdf`` expands one only with ``trust=True``; a trusted
expansion still never opens a FIFO, device or directory (it would block or never end) and stops
within seconds when macros run away (:data:`jaxkin.urdf.XACRO_TIME_LIMIT`,
:data:`jaxkin.urdf.XACRO_MAX_ELEMENTS`, ``max_bytes`` per expression). Oracles: a marker file the
hostile expression creates (absent without trust, present with it: the payload really runs code);
the clock; a watchdog inside xacro that stops a runaway expansion the library failed to stop, so
that a regression fails instead of hanging the suite."""

from __future__ import annotations

import os
import threading
import time

import pytest

import jaxkin as jk
import jaxkin.urdf as ju
from jaxkin.urdf import URDFError

pytest.importorskip("xacro")

HEADER = '<?xml version="1.0"?>\n<robot name="r" xmlns:xacro="http://www.ros.org/wiki/xacro">\n'


def _os_class() -> str:
    """The name of a class whose ``__init__.__globals__`` holds ``os`` (found as an attacker
    would, by walking ``object.__subclasses__()``)."""
    seen = set()
    for cls in object.__subclasses__():  # the first class of each name, as the payload finds it
        if cls.__name__ not in seen and "os" in getattr(cls.__init__, "__globals__", {}):
            return cls.__name__
        seen.add(cls.__name__)
    raise AssertionError("no class reaches os")  # pragma: no cover


def _attack(tmp_path):
    """A xacro file whose link name is an expression that creates ``marker`` through ``os``,
    reached without any ``__`` name in the top-level expression (xacro refuses those, but not
    inside a lambda)."""
    marker = tmp_path / "marker"
    payload = (
        "(lambda: [c for c in ().__class__.__base__.__subclasses__() "
        f"if c.__name__ == '{_os_class()}'][0].__init__.__globals__['os']"
        f".mkdir({str(marker)!r}))()"
    )
    path = tmp_path / "robot.urdf.xacro"
    path.write_text(HEADER + f'  <link name="${{{payload}}}"/>\n</robot>\n')
    return path, marker


def test_an_untrusted_xacro_is_refused_and_runs_nothing(tmp_path):
    path, marker = _attack(tmp_path)
    for kwargs in ({}, {"xacro_args": {"x": "1"}}, {"trust": False}):
        with pytest.raises(URDFError) as e:
            jk.load_urdf(path, **kwargs)
        assert e.value.file == str(path)
        message = str(e.value)
        for words in ("xacro", "Python", "any code", "trust=True", "only for files you trust"):
            assert words in message
        assert not marker.exists()
    with pytest.raises(URDFError, match=r"trust=True"):
        jk.load_urdf(str(path))  # a str path as well
    assert not marker.exists()
    # the payload is real: trusted, it runs (the code above is what refusing prevents)
    robot = jk.load_urdf(path, trust=True)
    assert marker.is_dir() and robot.frame_names == ("None",)


def test_trust_must_be_a_bool(tmp_path):
    path, marker = _attack(tmp_path)
    for bad in ("yes", 1, None):
        with pytest.raises(jk.ModelError, match=r"trust must be True or False"):
            jk.load_urdf(path, trust=bad)
    with pytest.raises(jk.ModelError, match=r"trust must be True or False"):
        jk.load_urdf('<robot name="r"><link name="a"/></robot>', trust="no")
    assert not marker.exists()
    # trust=True on a plain URDF changes nothing
    plain = '<robot name="r"><link name="a"/></robot>'
    assert jk.load_urdf(plain, trust=True) == jk.load_urdf(plain)


def _load_in_thread(path, unblock, **kwargs):
    """``load_urdf(path, trust=True)`` in a thread; after 20 s, ``unblock()`` (a hung read of a
    FIFO gets its end of file) so that a regression fails instead of hanging."""
    outcome = {}

    def run():
        try:
            outcome["robot"] = jk.load_urdf(path, trust=True, **kwargs)
        except Exception as e:
            outcome["error"] = e

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    thread.join(20)
    hung = thread.is_alive()
    if hung:
        unblock()
        thread.join(20)
    assert not hung, "load_urdf blocked on a special file"
    return outcome


def _open_writer(fifo):
    def unblock():
        try:
            os.close(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK))
        except OSError:
            pass

    return unblock


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs os.mkfifo")
@pytest.mark.parametrize("where", ["include", "optional include", "top"])
def test_a_fifo_is_refused_before_reading(tmp_path, where):
    fifo = tmp_path / ("robot.urdf.xacro" if where == "top" else "macros.xacro")
    os.mkfifo(fifo)
    path = fifo
    if where != "top":
        optional = ' optional="true"' if where == "optional include" else ""
        path = tmp_path / "arm.urdf.xacro"
        path.write_text(
            HEADER + f'<xacro:include filename="macros.xacro"{optional}/>\n'
            '<link name="a"/>\n</robot>\n'
        )
    outcome = _load_in_thread(path, _open_writer(fifo))
    error = outcome.get("error")
    assert isinstance(error, URDFError), outcome
    assert error.file == str(path) and str(fifo) in str(error)
    assert "a FIFO" in str(error) and "not a regular file" in str(error)


@pytest.mark.parametrize("special", ["directory", "device"])
def test_other_special_files_are_refused_by_kind(tmp_path, special):
    target = tmp_path / "sub.xacro" if special == "directory" else "/dev/null"
    if special == "directory":
        target.mkdir()
    elif not os.path.exists(target):  # pragma: no cover - not a POSIX system
        pytest.skip("no /dev/null")
    path = tmp_path / "arm.urdf.xacro"
    path.write_text(HEADER + f'<xacro:include filename="{target}"/><link name="a"/></robot>\n')
    with pytest.raises(URDFError, match=rf"a {special}, not a regular file") as e:
        jk.load_urdf(path, trust=True)
    assert str(target) in str(e.value) and e.value.file == str(path)


def test_an_included_file_over_max_bytes_is_refused(tmp_path):
    (tmp_path / "big.xacro").write_text(HEADER + "<!--" + "x" * 5000 + "-->\n</robot>\n")
    path = tmp_path / "arm.urdf.xacro"
    path.write_text(HEADER + '<xacro:include filename="big.xacro"/><link name="a"/></robot>\n')
    with pytest.raises(URDFError, match=r"big\.xacro.*over the 4000-byte limit \(max_bytes\)"):
        jk.load_urdf(path, trust=True, max_bytes=4000)
    assert jk.load_urdf(path, trust=True).frame_names == ("a",)


class _Watchdog(Exception):
    pass


@pytest.fixture
def watchdog(monkeypatch):
    """Stops any xacro expansion after 30 s (the library's own caps must stop it far sooner):
    without it, a regression would expand 2^25 elements for hours."""
    import xacro

    real = xacro.eval_text
    deadline = time.monotonic() + 30

    def eval_text(*args, **kwargs):
        if time.monotonic() > deadline:
            raise _Watchdog("the test's watchdog stopped xacro after 30 s")
        return real(*args, **kwargs)

    monkeypatch.setattr(xacro, "eval_text", eval_text)


def _doubling(tmp_path, nested: bool):
    """A macro calling itself twice per level, 25 levels (2^25 links): flat (every link a
    child of ``<robot>``, which makes xacro quadratic) or nested (each copy in its own
    element)."""
    body = (
        '<a><xacro:d n="${n-1}"/></a><b><xacro:d n="${n-1}"/></b>'
        if nested
        else '<xacro:d n="${n-1}"/><xacro:d n="${n-1}"/>'
    )
    path = tmp_path / "doubling.urdf.xacro"
    path.write_text(
        HEADER + '<xacro:macro name="d" params="n">\n'
        f'<xacro:if value="${{n > 0}}">{body}</xacro:if>\n'
        '<xacro:unless value="${n > 0}"><link name="l"/></xacro:unless>\n'
        "</xacro:macro>\n"
        '<link name="base"/><xacro:d n="25"/>\n</robot>\n'
    )
    return path


def test_a_runaway_expansion_stops_at_the_time_limit(tmp_path, monkeypatch, watchdog):
    assert ju.XACRO_TIME_LIMIT == 10.0  # as documented
    monkeypatch.setattr(ju, "XACRO_TIME_LIMIT", 0.5)  # the default, 10 s, is too long a test
    path = _doubling(tmp_path, nested=False)
    start = time.monotonic()
    with pytest.raises(URDFError) as e:
        jk.load_urdf(path, trust=True)
    assert time.monotonic() - start < 5
    message = str(e.value)
    assert e.value.file == str(path) and "0.5 s" in message
    for words in ("XACRO_TIME_LIMIT", "xacro", "> robot.urdf"):
        assert words in message


def test_a_runaway_expansion_stops_at_the_element_cap(tmp_path, monkeypatch, watchdog):
    assert ju.XACRO_MAX_ELEMENTS == 100_000  # as documented
    monkeypatch.setattr(ju, "XACRO_MAX_ELEMENTS", 2000)  # the default takes seconds to reach
    path = _doubling(tmp_path, nested=True)
    start = time.monotonic()
    with pytest.raises(URDFError) as e:
        jk.load_urdf(path, trust=True)
    assert time.monotonic() - start < 5
    message = str(e.value)
    assert e.value.file == str(path) and "2000 elements" in message
    for words in ("XACRO_MAX_ELEMENTS", "> robot.urdf"):
        assert words in message


def test_an_expression_over_max_bytes_stops_the_expansion(tmp_path, watchdog):
    """A string property doubled at each level: refused as soon as one value is over
    ``max_bytes``, while the expansion runs (here 20 levels, 8 MB; with 40, 8 TB would exhaust
    the memory before the expanded document could be measured)."""
    props = "".join(
        f'<xacro:property name="s{i + 1}" value="${{s{i} + s{i}}}"/>' for i in range(20)
    )
    path = tmp_path / "strings.urdf.xacro"
    path.write_text(
        HEADER
        + '<xacro:property name="s0" value="xxxxxxxx"/>'
        + props
        + '<link name="${s20}"/>\n</robot>\n'
    )
    with pytest.raises(URDFError, match=r"an expression.*over the 10000-byte limit \(max_bytes\)"):
        jk.load_urdf(path, trust=True, max_bytes=10_000)


def test_the_hooks_are_removed_after_each_call(tmp_path, monkeypatch):
    """xacro's functions are left as they were, after a success and after a refusal."""
    import xacro

    def functions():
        return {k: v for k, v in vars(xacro).items() if callable(v)}

    before = functions()
    path = tmp_path / "ok.urdf.xacro"
    path.write_text(HEADER + '<link name="a"/>\n</robot>\n')
    assert jk.load_urdf(path, trust=True).frame_names == ("a",)
    monkeypatch.setattr(ju, "XACRO_MAX_ELEMENTS", 1)
    with pytest.raises(URDFError, match="XACRO_MAX_ELEMENTS"):
        jk.load_urdf(path, trust=True)
    assert functions() == before and "open" not in before
