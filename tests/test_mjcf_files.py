"""MJCF files as untrusted input (jaxkin.mjcf.check_files, run by jk.load_mjcf before MuJoCo reads
anything): an ``<include>`` or ``<asset><model>`` file that is a FIFO, a device or a directory is
refused by name, wherever MuJoCo would look for it (relative to the top file's directory, then to
the including file's), instead of hanging; the bytes read in all are capped; and the number of
bodies (MuJoCo's parser is quadratic in it) is capped at ``max_bodies``, counting includes,
``<replicate count>`` and attached models. Each call that could hang runs under a time guard."""

from __future__ import annotations

import os
import time

import mujoco
import pytest
from _blocking import raised_within

import jaxkin as jk
import jaxkin.mjcf as jmjcf
from jaxkin.mjcf import MJCFError

G = '<geom size=".05"/>'
pytestmark = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs os.mkfifo (POSIX)")


def _mujoco(*parts: str) -> str:
    return "<mujoco>" + "".join(parts) + "</mujoco>"


def _arm(name: str = "a") -> str:
    return _mujoco(f'<worldbody><body name="{name}"><joint/>{G}</body></worldbody>')


def test_include_of_a_fifo_is_refused_by_name(tmp_path):
    fifo = tmp_path / "arm.xml"
    os.mkfifo(fifo)
    main = tmp_path / "scene.xml"
    main.write_text(_mujoco('<worldbody><include file="arm.xml"/></worldbody>'))
    e = raised_within(lambda: jk.load_mjcf(main), [fifo])
    assert isinstance(e, MJCFError), e
    assert "arm.xml" in str(e) and "not a regular file" in str(e) and "FIFO" in str(e)
    assert e.file == str(main) and e.element == "<include file='arm.xml'>"


def test_nested_include_resolved_beside_the_including_file(tmp_path):
    """MuJoCo looks for a nested include in the top file's directory, then in the including
    file's: ``sub/inner.xml``, a FIFO, is what it would open."""
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "arm.xml").write_text(
        _mujoco(f'<worldbody><body name="a">{G}<include file="inner.xml"/></body></worldbody>')
    )
    fifo = tmp_path / "sub" / "inner.xml"
    os.mkfifo(fifo)
    main = tmp_path / "scene.xml"
    main.write_text(_mujoco('<worldbody><include file="sub/arm.xml"/></worldbody>'))
    e = raised_within(lambda: jk.load_mjcf(main), [fifo])
    assert isinstance(e, MJCFError) and "inner.xml" in str(e) and "not a regular file" in str(e)


def test_model_asset_symlink_and_string_source(tmp_path, monkeypatch):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    (tmp_path / "link.xml").symlink_to(fifo)
    # <asset><model file=...>: MuJoCo reads it while parsing, too.
    attach = tmp_path / "attach.xml"
    attach.write_text(_mujoco('<asset><model name="m" file="link.xml"/></asset>', _arm()))
    e = raised_within(lambda: jk.load_mjcf(attach), [fifo])
    assert isinstance(e, MJCFError) and "link.xml" in str(e) and "not a regular file" in str(e)
    # XML given as a string: its includes are relative to the current directory.
    monkeypatch.chdir(tmp_path)
    xml = _mujoco('<worldbody><include file="pipe"/></worldbody>')
    e = raised_within(lambda: jk.load_mjcf(xml), [fifo])
    assert isinstance(e, MJCFError) and "'pipe'" in str(e) and e.file == "<string>"
    # A directory, and the top file itself being a FIFO.
    (tmp_path / "dir.xml").mkdir()
    xml = _mujoco('<worldbody><include file="dir.xml"/></worldbody>')
    e = raised_within(lambda: jk.load_mjcf(xml))
    assert isinstance(e, MJCFError) and "directory" in str(e)
    e = raised_within(lambda: jk.load_mjcf(fifo), [fifo])
    assert isinstance(e, MJCFError) and "not a regular file" in str(e)


def test_includes_outside_the_directory_stay_allowed(tmp_path):
    """MuJoCo allows ``../`` includes and models use them (the Franka Kitchen's
    ``../franka_assets/chain.xml``): still loaded; a missing include is MuJoCo's message."""
    (tmp_path / "parts").mkdir()
    (tmp_path / "parts" / "arm.xml").write_text(_mujoco(f'<body name="a"><joint/>{G}</body>'))
    (tmp_path / "scene").mkdir()
    main = tmp_path / "scene" / "scene.xml"
    main.write_text(_mujoco('<worldbody><include file="../parts/arm.xml"/></worldbody>'))
    assert jk.load_mjcf(main).frame_names == ("world", "a")


def test_total_bytes_read_are_capped(tmp_path, monkeypatch):
    monkeypatch.setattr(jmjcf, "MAX_BYTES", 600)
    (tmp_path / "a.xml").write_text(_arm("a") + " " * 300)
    (tmp_path / "b.xml").write_text(_arm("b") + " " * 300)
    main = tmp_path / "scene.xml"
    main.write_text(
        _mujoco('<worldbody><include file="a.xml"/><include file="b.xml"/></worldbody>')
    )
    with pytest.raises(MJCFError, match=r"more than 600 bytes.*b\.xml"):
        jk.load_mjcf(main)
    assert jk.load_mjcf(tmp_path / "a.xml").frame_names == ("world", "a")


def _flat(n: int) -> str:
    bodies = "".join(f'<body name="b{i}">{G}</body>' for i in range(n))
    return _mujoco(f"<worldbody>{bodies}</worldbody>")


def test_too_many_bodies_refused_fast_naming_cap_count_file_and_fix(tmp_path):
    path = tmp_path / "many.xml"
    n = jmjcf.MAX_BODIES + 1
    path.write_text(_flat(n))
    start = time.perf_counter()
    with pytest.raises(MJCFError) as e:
        jk.load_mjcf(path)
    elapsed = time.perf_counter() - start
    text = str(e.value)
    assert str(path) in text and f"{n} bodies" in text
    assert f"max_bodies={jmjcf.MAX_BODIES}" in text and f"max_bodies={n}" in text
    assert e.value.file == str(path)
    assert elapsed < 2.0, f"refused after {elapsed:.1f} s: MuJoCo was asked to parse it"
    assert jmjcf.MAX_BODIES == 5_000


def test_max_bodies_keyword_counts_includes_replicate_and_attach(tmp_path):
    arm = f'<body name="a"><joint/>{G}<body name="b"><joint/>{G}</body></body>'
    (tmp_path / "arm.xml").write_text(_mujoco(arm))  # a fragment, spliced into <worldbody>
    (tmp_path / "model.xml").write_text(_mujoco(f"<worldbody>{arm}</worldbody>"))
    main = tmp_path / "scene.xml"
    main.write_text(_mujoco('<worldbody><include file="arm.xml"/></worldbody>'))
    with pytest.raises(MJCFError, match=r"2 bodies, more than max_bodies=1"):
        jk.load_mjcf(main, max_bodies=1)
    assert jk.load_mjcf(main, max_bodies=2).joint_names == ("joint0", "joint1")
    # <replicate count> multiplies what it holds (nested: 40 * 30 = 1200, plus the top body),
    # refused without building anything; an attached model counts once per <attach>.
    rep = _mujoco(
        f'<worldbody><body name="top">{G}</body><replicate count="40" offset="1 0 0">'
        f'<replicate count="30" offset="0 1 0"><body name="r">{G}</body></replicate>'
        "</replicate></worldbody>"
    )
    with pytest.raises(MJCFError, match=r"1201 bodies, more than max_bodies=1200"):
        jmjcf.check_files(rep, max_bodies=1200)
    jmjcf.check_files(rep, max_bodies=1201)
    attach = tmp_path / "attach.xml"
    attach.write_text(
        _mujoco(
            '<asset><model name="m" file="model.xml"/></asset><worldbody>'
            f'<body name="x">{G}<attach model="m" prefix="p"/></body>'
            f'<body name="y">{G}<attach model="m" prefix="q"/></body></worldbody>'
        )
    )
    assert mujoco.MjModel.from_xml_path(str(attach)).nbody - 1 == 6
    with pytest.raises(MJCFError, match=r"6 bodies"):
        jmjcf.check_files(attach, max_bodies=5)
    jmjcf.check_files(attach, max_bodies=6)
    for bad in (0, -3, 2.5, "10", True, None):
        with pytest.raises(jk.JaxkinError, match="max_bodies must be a positive int"):
            jk.load_mjcf(main, max_bodies=bad)


def test_bytes_that_are_not_utf8_are_a_jaxkin_error():
    with pytest.raises(MJCFError, match="not UTF-8"):
        jk.load_mjcf(b"<mujoco model='\xff'><worldbody/></mujoco>")
