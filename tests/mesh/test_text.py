"""Numbers as text (``mesh.formats._text``): every integer exact, every float to 13 digits, and
the blocks it cannot write handed back to ``%`` formatting."""

from __future__ import annotations

import io

import numpy as np
import pytest

from napari_swa_imesh.mesh.formats._text import _digits8, int_rows, sci_rows
from napari_swa_imesh.mesh.formats._triangle_tetgen import write_rows


def _parse_ints(data: bytes, sep: bytes) -> np.ndarray:
    lines = data.decode().splitlines()
    return np.array([[int(f) for f in line.split(sep.decode().strip() or None)]
                     for line in lines])


def test_every_8_digit_number_is_its_decimal_text():
    # all of 0 .. 10**8 in strides that visit every digit position and carry
    x = np.concatenate([np.arange(0, 10 ** 8, 9973), np.arange(100000),
                        10 ** np.arange(9)[:-1] - 1, 10 ** np.arange(8)]).astype(np.uint64)
    text = _digits8(x).view("S8")
    assert text.tolist() == [b"%8d" % v for v in x.tolist()]
    assert _digits8(x, blank=False).view("S8").tolist() == [b"%08d" % v for v in x.tolist()]


@pytest.mark.parametrize("top", [10, 10 ** 8, 10 ** 16])
@pytest.mark.parametrize("sep", [b" ", b", "])
def test_int_rows_read_back_exactly(top, sep):
    rng = np.random.default_rng(top)
    block = rng.integers(0, top, (3000, 5), dtype=np.int64)
    block[:4, 0] = [0, top - 1, 10 ** min(15, len(str(top)) - 1), 1]
    data = int_rows(block, sep)
    assert np.array_equal(_parse_ints(data, sep), block)
    lines = data.splitlines(keepends=True)
    assert len(lines) == len(block)
    assert all(line.endswith(b"\n") and not line.rstrip().endswith(b",") for line in lines)
    # each column as wide as its widest number, no wider
    widths = [max(len(str(v)) for v in col) for col in block.T.tolist()]
    assert {len(line) for line in lines} == {sum(widths) + len(sep) * (len(widths) - 1) + 1}


def test_int_rows_leaves_what_it_cannot_write_to_percent_formatting():
    assert int_rows(np.array([[1, -2]]), b" ") is None
    assert int_rows(np.array([[10 ** 16]]), b" ") is None
    assert int_rows(np.array([[1.0]]), b" ") is None
    with pytest.raises(ValueError, match="separator of one or two bytes"):
        int_rows(np.array([[1, 2]]), b"")
    fh = io.StringIO()
    write_rows(fh, np.array([[3, -2], [10 ** 17, 0]]))
    assert fh.getvalue() == "3 -2\n100000000000000000 0\n"


def test_sci_rows_has_13_correct_digits():
    rng = np.random.default_rng(1)
    mags = 10.0 ** rng.integers(-29, 29, 40000)
    values = (rng.random(40000) * 9 + 1) * mags * np.sign(rng.standard_normal(40000))
    values[:8] = [0.0, 1.0, -1.0, 9.9999999999995, 9.99999999999949, 0.1, 1e-30, 9.99e29]
    values = values.reshape(-1, 4)
    ids = np.arange(1, len(values) + 1)
    data = sci_rows(ids, values)
    rows = [line.split(b",") for line in data.splitlines()]
    assert [int(r[0]) for r in rows] == ids.tolist()
    back = np.array([[float(f) for f in r[1:]] for r in rows])
    # within half a unit of the 13th significant digit (a near-tie may round either way)
    unit = 10.0 ** (np.floor(np.log10(np.where(values == 0, 1, np.abs(values)))) - 12)
    assert (np.abs(back - values) <= 0.501 * unit).all()
    assert (back[values == 0] == 0).all()
    reference = [[float("%.12e" % v) for v in row] for row in values.tolist()]
    assert (back == np.array(reference)).mean() > 0.999   # ties may round the other way
    assert all(len(f) == 20 for r in rows for f in r[1:])  # ", " + 18 + sign: CalculiX's 20


@pytest.mark.parametrize("bad", [np.nan, np.inf, 1e31, 1e-31])
def test_sci_rows_leaves_what_it_cannot_write_to_percent_formatting(bad):
    values = np.array([[1.0, bad, 2.0]])
    assert sci_rows(np.array([1]), values) is None
    fh = io.StringIO()
    write_rows(fh, np.array([[1]]), values, sep=", ", float_format="%.12e")
    assert fh.getvalue() == "1, %.12e, %.12e, %.12e\n" % (1.0, bad, 2.0)


def test_write_rows_keeps_the_order_of_text_and_bytes_in_a_file(tmp_path):
    path = tmp_path / "rows.txt"
    with open(path, "w") as fh:
        fh.write("head\n")
        write_rows(fh, np.array([[1, 2]]))
        fh.write("middle\n")
        write_rows(fh, np.array([[7]]), np.array([[0.25]]), sep=", ", float_format="%.12e")
        fh.write("tail\n")
    assert path.read_text().splitlines() == [
        "head", "1 2", "middle", "7,  2.500000000000e-01", "tail"]


@pytest.mark.parametrize("first", [0, 10 ** 8 - 20])
def test_abaqus_id_lines_stay_within_256_characters(first):
    from napari_swa_imesh.mesh.formats._abaqus import _write_ids

    ids = np.arange(first, first + 45)
    fh = io.StringIO()
    _write_ids(fh, ids)
    lines = fh.getvalue().splitlines()
    assert max(len(line) for line in lines) <= 256
    back = [int(f) for line in lines for f in line.split(",")]
    assert back == (ids + 1).tolist()
