"""CSV results are untrusted text: names and comments cannot forge rows, and what the writer
writes (names with ',', '"', line breaks, '#', any Unicode; float64 values) reads back exactly,
with jaxkin.io.csv_records and with jaxkin.io.read_configurations (the command line's reader)."""

import os
import types

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import jaxkin as jk
from jaxkin import cli
from jaxkin.io import ResultWriter, csv_records, read_configurations

# Characters that break naive CSV, among any others (lone surrogates excepted: UTF-8 cannot
# carry them, and the writer refuses them by name).
HOSTILE = st.sampled_from([",", '"', "\n", "\r", "\r\n", "#", " ", "\\", "\ufeff", "\u2028", "é"])
TEXT = st.lists(st.one_of(HOSTILE, st.characters(blacklist_categories=("Cs",))), max_size=6)
TEXT = TEXT.map("".join)
VALUES = st.floats(allow_nan=False, width=64)
FINITE = st.floats(allow_nan=False, allow_infinity=False, width=64)  # configurations


def read_back(path):
    """(comments, header, rows) as the command line opens a CSV file."""
    comments = []
    with open(path, encoding="utf-8-sig", errors="replace", newline="") as f:
        records = [fields for _, fields in csv_records(f, source=path, comments=comments)]
    return comments, records[0], records[1:]


@given(
    names=st.lists(TEXT, min_size=1, max_size=4),
    comments=st.lists(TEXT, max_size=3),
    data=st.data(),
)
def test_names_comments_and_values_round_trip(tmp_path_factory, names, comments, data):
    n = data.draw(st.integers(0, 3))
    x = np.array(data.draw(st.lists(VALUES, min_size=n * len(names), max_size=n * len(names))))
    x = x.reshape(n, len(names))
    path = tmp_path_factory.mktemp("csv") / "r.csv"
    fields = {"x": ((len(names),), "float64")}
    with ResultWriter(path, fields, n, columns={"x": names}, comments=comments) as w:
        w.append({"x": x})
        w.commit()
    got_comments, header, rows = read_back(path)
    assert got_comments == comments and header == names and len(rows) == n
    got = np.array([[float(v) for v in row] for row in rows]).reshape(n, len(names))
    np.testing.assert_array_equal(got.view(np.int64), x.view(np.int64))  # bit for bit


@given(
    joints=st.lists(TEXT, min_size=1, max_size=3, unique=True),
    robot_name=TEXT,
    data=st.data(),
)
def test_the_command_line_reads_back_configurations_it_could_write(
    tmp_path_factory, joints, robot_name, data
):
    """Columns q_<joint> and qd_<joint> whatever the joint names, as `jaxkin velocities` writes
    them (its robot name in a comment)."""
    dof, n = len(joints), data.draw(st.integers(1, 3))
    q, qd = (
        np.array(data.draw(st.lists(FINITE, min_size=n * dof, max_size=n * dof))).reshape(n, dof)
        for _ in range(2)
    )
    path = tmp_path_factory.mktemp("csv") / "c.csv"
    fields = {"q": ((dof,), "float64"), "qd": ((dof,), "float64")}
    columns = {"q": [f"q_{j}" for j in joints], "qd": [f"qd_{j}" for j in joints]}
    comments = [f"jaxkin velocities: robot = {robot_name}"]
    with ResultWriter(path, fields, n, columns=columns, comments=comments) as w:
        w.append({"q": q, "qd": qd})
        w.commit()
    robot = types.SimpleNamespace(name=robot_name, joint_names=tuple(joints), dof=dof)
    got_q, got_qd = read_configurations(str(path), robot, np.float64)
    np.testing.assert_array_equal(got_q.view(np.int64), q.view(np.int64))
    np.testing.assert_array_equal(got_qd.view(np.int64), qd.view(np.int64))


def test_a_robot_name_with_a_newline_writes_no_row(tmp_path):
    """`<robot name="arm&#10;1,2,3">`: its comment stays one line; the file has 1 row."""
    name = "arm\n1,2,3\r\n4,5,6\u2028# \\n"
    fields = {"q": ((3,), "float64")}
    path = tmp_path / "r.csv"
    with ResultWriter(path, fields, 1, meta={"robot": name}) as w:  # comments from meta
        w.append({"q": np.array([[0.5, 0.25, -1.0]])})
        w.commit()
    lines = path.read_bytes().split(b"\n")
    assert lines == [
        b"# robot = arm\\n1,2,3\\r\\n4,5,6\\u2028# \\\\n",
        b"q_1,q_2,q_3",
        b"0.5,0.25,-1",
        b"",
    ]
    comments, header, rows = read_back(path)
    assert comments == [f"robot = {name}"] and header == ["q_1", "q_2", "q_3"]
    assert rows == [["0.5", "0.25", "-1"]]


@pytest.mark.parametrize(
    ("names", "first_line"),
    [
        (["a,b", 'c"d', "e\nf"], '"a,b","c""d","e'),
        (["g\rh", "i"], '"g'),
        (["#j", "k"], '"#j","k"'),  # not a comment line
        ([" #l"], '" #l"'),
        (["  "], '"  "'),  # not a blank line
        (["\ufeffm", "n"], '"\ufeffm","n"'),  # not a byte order mark
        (["o\u2028p", "q"], "o\u2028p,q"),  # the csv module's rule: only \r and \n are breaks
    ],
)
def test_header_is_quoted_where_it_must_be(tmp_path, names, first_line):
    path = tmp_path / "h.csv"
    with ResultWriter(path, {"x": ((len(names),), "float64")}, 0, columns={"x": names}) as w:
        w.commit()
    text = path.read_bytes().decode()
    assert text.startswith(first_line)
    assert read_back(path)[1:] == (names, [])


def test_comment_lines_only_where_a_record_starts():
    """A '#' after a line break inside quotes is data; one starting a record is a comment; the
    command line's old reader dropped the former and broke the header."""
    comments = []
    text = ['"a\n', '#b",c\n', "# d \\t\\x1b\\\\\n", "\n", "  # e\n", "1,2\n"]
    records = list(csv_records(text, comments=comments))
    assert records == [(1, ["a\n#b", "c"]), (6, ["1", "2"])]
    assert comments == ["d \t\x1b\\", "e"]


@pytest.mark.parametrize("bad", ['"3,4\n', '"3" ,4\n'])
def test_malformed_csv_names_the_source_and_line(bad):
    with pytest.raises(jk.JaxkinError, match=r"^f\.csv line 3: .*check its quotes"):
        list(csv_records(["x,y\n", "1,2\n", bad], source="f.csv"))


def test_a_name_utf8_cannot_carry_is_refused(tmp_path):
    with pytest.raises(jk.JaxkinError, match="lone surrogate"):
        ResultWriter(tmp_path / "r.csv", {"x": ((1,), "float64")}, 1, columns={"x": ["\ud800"]})
    assert os.listdir(tmp_path) == []


HOSTILE_URDF = """<?xml version="1.0"?>
<robot name="arm&#10;1,2,3,4,5,6,7,8,9,10,11,12,13">
  <link name="base"/><link name="upper"/><link name="hand"/>
  <joint name="a,&quot;b&quot;&#10;#c" type="revolute">
    <parent link="base"/><child link="upper"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/>
  </joint>
  <joint name="#d&#13;&#233;" type="revolute">
    <parent link="upper"/><child link="hand"/>
    <origin xyz="0.3 0 0" rpy="0 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/>
  </joint>
</robot>
"""


def test_velocities_csv_of_a_robot_with_hostile_names(tmp_path, monkeypatch, capsys):
    """The issue's case end to end: the robot name's newline forges no row, the joint names'
    commas, quotes and line breaks neither split nor shift a column."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "arm.urdf").write_text(HOSTILE_URDF)
    assert cli.main(["velocities", "arm.urdf", "--n", "3", "--output", "v.csv"]) == 0
    capsys.readouterr()
    comments, header, rows = read_back(tmp_path / "v.csv")
    joints = ['a,"b"\n#c', "#d\ré"]
    assert "jaxkin velocities: robot = arm\n1,2,3,4,5,6,7,8,9,10,11,12,13" in comments
    assert header[:4] == [f"q_{j}" for j in joints] + [f"qd_{j}" for j in joints]
    assert header[4:] == ["vx", "vy", "vz", "wx", "wy", "wz", "sigma_1", "sigma_2", "margin"]
    q = np.array(rows, dtype=float)[:, :2]  # 3 rows of 13 numbers each
    assert q.shape == (3, 2) and np.all(np.abs(q) <= 3)  # sampled within the limits


def test_joint_names_that_look_like_columns(tmp_path):
    """Joints 'a' and 'q_a': jaxkin's q_<joint> reading wins where every column has it."""
    joints = ("a", "q_a", " b ")
    columns = {"q": [f"q_{j}" for j in joints], "qd": [f"qd_{j}" for j in joints]}
    fields = {"q": ((3,), "float64"), "qd": ((3,), "float64")}
    with ResultWriter(tmp_path / "c.csv", fields, 1, columns=columns) as w:
        w.append({"q": np.array([[1.0, 2.0, 3.0]]), "qd": np.array([[4.0, 5.0, 6.0]])})
        w.commit()
    robot = types.SimpleNamespace(name="r", joint_names=joints, dof=3)
    q, qd = read_configurations(str(tmp_path / "c.csv"), robot, np.float64)
    assert q.tolist() == [[1.0, 2.0, 3.0]] and qd.tolist() == [[4.0, 5.0, 6.0]]
    (tmp_path / "d.csv").write_text("q_a, a , b \n1,2,3\n")  # hand-written: names as given
    q, qd = read_configurations(str(tmp_path / "d.csv"), robot, np.float64)
    assert q.tolist() == [[2.0, 1.0, 3.0]] and qd is None
