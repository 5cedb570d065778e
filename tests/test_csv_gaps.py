"""A CSV file with gaps (`nan`, empty fields, rows of empty fields: the documented gap
convention of `hrgjax allan`, `hg.imu.load`, `hg.load`) takes the numeric fast path
(`hrgjax._csv_numeric`, NumPy's C parser in chunks) and reads exactly as the validating
reader (Python's csv module, the second method) reads it; errors still name the file's line.
Audit: one NaN sent a whole file to the validating reader, ≈ 6× the time and memory."""

import tracemalloc

import numpy as np
import pytest

import hrgjax as hg
from hrgjax import _csv_numeric, _data_files
from hrgjax._data_files import read_csv_table

HEADER = "time_s,temperature_c,table_rate_dps,wave_angle_deg"
# comments, blank lines, CRLF, `nan` in every case, empty and blank fields, a row of empty
# fields among the samples (a gap) and after them (a spreadsheet's), numbers in odd forms
GAPPED = (
    "# a log with gaps é\r\n\r\n"
    f"{HEADER},x\r\n"
    "0,20,0,0,1\r\n"
    "0.1,20,,0.5,nan\r\n"
    "  # a note\r\n"
    "0.2,20, ,1e-3,NaN\r\n"
    ",,,,\r\n"
    "\t\r\n"
    "0.4,-nan,+1.5, 2 ,\t\r\n"
    "0.5,20,3,-1,-Infinity\r\n"
    ",,,,\r\n"
    " , ,,,\r\n"
)
ROWS, LINES = 6, [4, 5, 7, 8, 10, 11]


def read(path, monkeypatch, fast, **kwargs):
    """`read_csv_table` and whether the fast path gave its result (`fast=False`: the
    validating reader alone)."""
    real, taken = _data_files._numeric_table, []
    if fast:
        monkeypatch.setattr(_data_files, "_numeric_table",
                            lambda p, *a: taken.append(real(p, *a)) or taken[-1])  # fmt: skip
    else:
        monkeypatch.setattr(_data_files, "_numeric_table", lambda p, *a: None)
    try:
        return read_csv_table(str(path), **kwargs), bool(taken) and taken[-1] is not None
    finally:
        monkeypatch.setattr(_data_files, "_numeric_table", real)


@pytest.mark.parametrize("chunk", [1, 37, 1 << 20])
def test_gapped_file_takes_the_fast_path_and_reads_as_the_validating_reader(
    tmp_path, monkeypatch, chunk
):
    """Chunks of one line, of a few lines (rows split across chunks) and the whole file."""
    path = tmp_path / "g.csv"
    path.write_bytes(GAPPED.encode())
    monkeypatch.setattr(_csv_numeric, "CHUNK_BYTES", chunk)
    (fast, lines), took = read(path, monkeypatch, True, empty_as_nan=True)
    (slow, slow_lines), _ = read(path, monkeypatch, False, empty_as_nan=True)
    assert took
    assert lines.tolist() == slow_lines.tolist() == LINES
    assert list(fast) == list(slow) == [*HEADER.split(","), "x"]
    for k in slow:
        assert fast[k].dtype == slow[k].dtype == np.float64, k
        np.testing.assert_array_equal(fast[k], slow[k])
    # by hand: the gaps are NaN, the row of empty fields a row of NaN
    np.testing.assert_array_equal(fast["table_rate_dps"], [0, np.nan, np.nan, np.nan, 1.5, 3])
    np.testing.assert_array_equal(fast["x"], [1, np.nan, np.nan, np.nan, np.nan, -np.inf])
    assert np.isnan(fast["temperature_c"][3:5]).all()


def test_gapped_file_without_empty_as_nan_is_refused_naming_the_line(tmp_path, monkeypatch):
    """Without `empty_as_nan` (`hg.load`, `hg.imu.load`) an empty field or a row of empty
    fields among the samples is refused as before, naming the line; `nan` is read (and then
    refused by `MeasuredData`, naming the line) on the fast path."""
    path = tmp_path / "g.csv"
    path.write_bytes(GAPPED.encode())
    for fast in (True, False):
        with pytest.raises(ValueError, match=r"g\.csv: line 8: every field is empty"):
            read(path, monkeypatch, fast)
    path.write_text(f"{HEADER}\n0,20,0,0\n# c\n0.1,20, ,0\n0.2,20,0,0\n")
    want = r"g\.csv: column 'table_rate_dps' row 1 \(line 4\): ' ' is not a number in \[°/s\]"
    for fast in (True, False):
        with pytest.raises(ValueError, match=want):
            read(path, monkeypatch, fast)
    path.write_text(f"# made by hand\n{HEADER}\n0,20,0,0\n\n0.1,20,0,0\n0.2,nan,0,0\n")
    (cols, lines), took = read(path, monkeypatch, True)
    assert took and lines.tolist() == [3, 5, 6] and np.isnan(cols["temperature_c"][2])
    with pytest.raises(ValueError, match=r"non-finite value \(nan\) at row 2 \(line 6 of the"):
        hg.load(path)


def test_fast_path_keeps_the_exact_integer_checks_with_gaps(tmp_path, monkeypatch):
    """A gap (NaN) does not hide an integer beyond 2**53 from the exact check, which the
    validating reader then names; nanosecond stamps with a gap read as offsets."""
    path = tmp_path / "n.csv"
    path.write_text("t,y\n1,nan\n2,9007199254740993\n3,\n")
    want = r"column 'y' row 1 \(line 3\): the integer 9007199254740993 is too large"
    with pytest.raises(ValueError, match=want):
        read_csv_table(str(path), empty_as_nan=True, exact_integers=["y"])
    path.write_text("t,y\n1700000000000000001,nan\n1700000000000000003,\n")
    cols, _ = read_csv_table(str(path), empty_as_nan=True, integer_offsets=["t"])
    assert cols["t"].tolist() == [0.0, 2.0]


def test_a_line_beyond_the_field_limit_is_named_not_cut(tmp_path, monkeypatch):
    """A line the csv module refuses (over its field limit) ends the fast path's read there
    and is left to the validating reader, which names it: the rows before it are not
    returned as the whole file."""
    path = tmp_path / "l.csv"
    path.write_text("a,b\n1,nan\n2," + "1" * 140_000 + "\n3,\n")
    want = r"l\.csv: line 3: not a readable CSV row \(field larger than field limit"
    for chunk in (1, 1 << 20):
        monkeypatch.setattr(_csv_numeric, "CHUNK_BYTES", chunk)
        for fast in (True, False):
            with pytest.raises(ValueError, match=want):
                read(path, monkeypatch, fast, empty_as_nan=True)


def test_gapped_read_holds_the_table_not_a_string_per_field(tmp_path):
    """Traced memory of a gapped 100 000-row read: a few times the float table (3.2 MB),
    where the validating reader held ≈ 600 bytes a row (a list and four strings)."""
    n = 100_000
    rng = np.random.default_rng(0)
    table = np.column_stack([np.arange(n) * 0.01, *rng.normal(size=(3, n))])
    table[n // 3, 2] = np.nan
    path = tmp_path / "big.csv"
    text = "\n".join(",".join(f"{v:.6f}" for v in row) for row in table.tolist())
    path.write_text(f"{HEADER}\n" + text.replace(",nan,", ",,", 1) + "\n")
    tracemalloc.start()
    try:
        cols, lines = read_csv_table(str(path), empty_as_nan=True)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert lines[-1] == n + 1 and np.isnan(cols["table_rate_dps"][n // 3])
    np.testing.assert_allclose(cols["wave_angle_deg"], table[:, 3], atol=5e-7)
    assert peak < 4 * table.nbytes, peak / 1e6


def test_long_reads_show_progress(tmp_path, monkeypatch):
    """A read of more than `PROGRESS_LINES` lines shows a bar (here over 5 lines), on both
    paths (the validating reader's second one over its columns), that reaches its total."""
    shown = []

    class Bar:
        def __init__(self, total, desc, unit):
            self.total, self.n = total, 0
            shown.append(self)

        def update(self, n):
            self.n += n

        def close(self):
            pass

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.close()

    monkeypatch.setattr(_csv_numeric, "PROGRESS_LINES", 5)
    monkeypatch.setattr(_data_files, "PROGRESS_LINES", 5)
    monkeypatch.setattr(_csv_numeric, "bar", Bar)
    monkeypatch.setattr(_data_files, "bar", Bar)
    path = tmp_path / "p.csv"
    path.write_text("a,b\n" + "1,\n" * 20)
    read(path, monkeypatch, True, empty_as_nan=True)
    assert [(b.total, b.n) for b in shown] == [(1, 1)]  # MB of the file
    read(path, monkeypatch, False, empty_as_nan=True)
    assert [(b.total, b.n) for b in shown[1:]] == [(21, 21), (2, 2)]  # lines, then columns
    path.write_text("a,b\n" + "1,\n" * 3)
    for fast in (True, False):
        read(path, monkeypatch, fast, empty_as_nan=True)
    assert len(shown) == 3
