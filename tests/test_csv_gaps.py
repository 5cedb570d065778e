"""A CSV file with gaps (`nan`, empty fields, rows of empty fields: the documented gap
convention of `hrgjax allan`, `hg.imu.load`, `hg.load`) takes the numeric fast path
(`hrgjax._csv_numeric`, NumPy's C parser in chunks) and reads exactly as the validating
reader (Python's csv module, the second method) reads it; errors still name the file's line.
Audit: one NaN sent a whole file to the validating reader, ≈ 6× the time and memory."""

import tracemalloc

import numpy as np
import pytest
from helpers import recording_bar

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

    Bar = recording_bar(shown)

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


def slow_reader_refused(monkeypatch):
    """Make the validating reader's column parsing fail loudly: a read that reaches it
    raises AssertionError (the fast path never calls it)."""

    def parse(*args, **kwargs):
        raise AssertionError("the validating reader ran")

    monkeypatch.setattr(_data_files, "_parse", parse)


def test_an_inf_stays_on_the_fast_path_where_no_integer_can_round_to_it(tmp_path, monkeypatch):
    """An inf is a rounded integer only where its text had 309 digits or more (2**1024 -
    2**970, half an ulp above the largest float, is the first integer a float64 rounds to
    inf); in a file of shorter lines it is the text `inf`, read on the fast path even in a
    column checked exactly (`hrgjax allan`'s), once, as the validating reader reads it.
    Audit: one inf sent a 3·10⁵-row log to the validating reader, 0.36 s → 5 s. A genuinely
    rounded integer is still refused, naming it, on both paths."""
    first = 2**1024 - 2**970
    assert float(str(first)) == np.inf and np.isfinite(float(str(first - 1)))
    path = tmp_path / "i.csv"
    path.write_text("t,y,run\n0,1,1\n1,inf,2\n2,,3\n3,-Infinity,inf\n")
    kwargs = dict(empty_as_nan=True, exact_integers=["t", "y"], integer_offsets=["t"])
    (slow, slow_lines), took = read(path, monkeypatch, False, **kwargs)
    assert not took and slow["y"][1] == np.inf and slow["run"].dtype == np.float64
    slow_reader_refused(monkeypatch)
    (fast, lines), took = read(path, monkeypatch, True, **kwargs)
    assert took and lines.tolist() == slow_lines.tolist() == [2, 3, 4, 5]
    for k in slow:
        assert fast[k].dtype == slow[k].dtype, k
        np.testing.assert_array_equal(fast[k], slow[k])
    monkeypatch.undo()
    for big in (first, first - 1, -first):  # rounded to inf, to the largest float, to -inf
        path.write_text(f"t,y\n0,inf\n1,{big}\n")
        want = rf"column 'y' row 1 \(line 3\): the integer {big} is too large to hold exactly"
        for fast in (True, False):
            with pytest.raises(ValueError, match=want):
                read(path, monkeypatch, fast, empty_as_nan=True, exact_integers=["y"])
    assert len(str(first)) == _data_files._INF_DIGITS == 309 and len(str(10**308)) == 309


@pytest.mark.parametrize("lead", ["\xa0", "\x0b", "\x0c", "\x1c", "\x85", "\u2003", "\u3000"])
def test_lines_before_the_header_strip_as_the_validating_readers(tmp_path, monkeypatch, lead):
    """Before the header the fast path skips what the validating reader skips (`str.strip`:
    every Unicode blank, not only space, tab and line ends): a comment behind a no-break
    space is a comment, so the numbers below it are refused as a header on both paths, and
    a line of a form feed alone is blank. Audit: the fast path read "\\xa0# a,b" as the
    header, columns '# a' and 'b'."""
    path = tmp_path / "h.csv"
    want = r"h\.csv: line 2, the header row, holds numbers \(1, 2\)"
    for text in (f"{lead}# a,b\n1,2\n3,4\n", f"{lead}\n1,2\n3,4\n"):
        path.write_text(text, encoding="utf-8")
        for fast in (True, False):
            with pytest.raises(ValueError, match=want):
                read(path, monkeypatch, fast)
    path.write_text(f"{lead}# a log\n{lead}\na,b\n1,2\n", encoding="utf-8")
    (cols, lines), took = read(path, monkeypatch, True)
    assert took and list(cols) == ["a", "b"] and lines.tolist() == [4]


@pytest.mark.parametrize("end", ["\n", "\r\n"])
def test_dense_empty_fields_are_filled_chunk_wide(tmp_path, monkeypatch, end):
    """A log with an empty field in every row (no blanks, a number on every line) is read
    a chunk at a time, its empty fields made `nan` in one `np.insert`, not line by line in
    Python (audit: 10⁶ × 7 in 10.7 s, where a clean file took 1–3 s); a chunk that also
    holds a row of empty fields or a blank line is read line by line, as before. Same
    columns and lines as the validating reader, at every chunk size."""
    rows = [",1,2", "3,,4", "5,6,", ",,7", "8,,", ",9,", "1e3,-inf,nan"]
    text = "time_s,temperature_c,table_rate_dps" + end + end.join(rows * 3) + end
    path = tmp_path / "d.csv"
    by_line = []
    real_line = _csv_numeric._Lines._line
    monkeypatch.setattr(
        _csv_numeric._Lines, "_line", lambda self, *a: by_line.append(1) or real_line(self, *a)
    )
    nan = np.nan
    want = np.array([[nan, 1, 2], [3, nan, 4], [5, 6, nan], [nan, nan, 7], [8, nan, nan],
                     [nan, 9, nan], [1e3, -np.inf, nan]] * 3)  # fmt: skip
    for gap_row, last_end in (("", end), ("", ""), (f",,{end}", end), (f"{end}", end)):
        body = text.replace(end + "3,,4", end + gap_row + "3,,4", 1)
        path.write_bytes((body[: -len(end)] + last_end).encode())
        (slow, slow_lines), _ = read(path, monkeypatch, False, empty_as_nan=True)
        for chunk in (1, 7, 1 << 18):
            monkeypatch.setattr(_csv_numeric, "CHUNK_BYTES", chunk)
            by_line.clear()
            (fast, lines), took = read(path, monkeypatch, True, empty_as_nan=True)
            assert took and lines.tolist() == slow_lines.tolist()
            assert bool(by_line) == bool(gap_row), (gap_row, chunk)  # (read line by line)
            for k in slow:
                np.testing.assert_array_equal(fast[k], slow[k])
            if not gap_row:
                np.testing.assert_array_equal(np.column_stack(list(fast.values())), want)
                assert lines.tolist() == list(range(2, 23))
        # without empty_as_nan the first empty field (or row of them) is refused, naming its
        # line, as the validating reader refuses it
        errors = []
        for fast in (True, False):
            with pytest.raises(ValueError, match=r"d\.csv: (column 'time_s' row 0 \()?line") as e:
                read(path, monkeypatch, fast)
            errors.append(str(e.value))
        assert errors[0] == errors[1]


NUMS = ["1", "-2.5", "3e-3", "+1", ".5", "5.", "1.e5", "0x10", "1_000", "nan(1)", "NaN", "-nan",
        "Infinity", "-inf", "INF", "infinit", "1e", ".", "-", "9007199254740993",
        "9007199254740992", "1700000000000000001", "1e16", "1e400", "-0", " 4 ", "\t4", " ",
        "\t", "1 2", "007", "--1", "nane", "a", "\xa01", '"1"', "#1"]  # fmt: skip
COMMON = ["1", "2", "-2.5", "nan", "", "", "0.25", "3", "inf"]
PRE = ["", "# top\n", "\n", "  # c\n", "\ufeff", "\ufeff# c\n", "\xa0# c\n", "\x0c\n", "\xa0\n",
       "\t\r\n", ",\n"]  # fmt: skip
NAMES = ["run", "time_s", "a", "b", "temperature_c", "eta", "nan", "1"]


def random_file(rng) -> tuple[str, dict]:
    """A small CSV text of samples with gaps, odd numbers, comments, blank lines and rows of
    empty fields, and the keywords of a read."""
    k = rng.choice([1, 2, 3, 4])
    ends = rng.choice([["\n"], ["\r\n"], ["\n", "\r\n"]])  # (mixed too)
    gaps_only = rng.random() < 0.5  # (a log with gaps and nothing else: chunks filled whole)

    def line():
        r = rng.random()
        if not gaps_only and r < 0.05:
            return rng.choice(["# note é", "  #x", "#"])
        if r < (0.02 if gaps_only else 0.08):
            return rng.choice(["", "  ", "\t"])
        if r < (0.04 if gaps_only else 0.13):
            return ",".join(rng.choice(["", " "]) for _ in range(k + rng.choice([0, 0, -1, 1])))
        pool = COMMON if gaps_only or rng.random() < 0.9 else NUMS
        fields = [rng.choice(pool) for _ in range(k)]
        if rng.random() < 0.02:
            fields = fields[: rng.choice([-1, k + 1])] or [""]
        return ",".join(fields)

    lines = [",".join(rng.sample(NAMES, k))] + [
        line() for _ in range(rng.choice([0, 2, 8, 20, 40]))
    ]
    text = "".join(ln + rng.choice(ends) for ln in lines)
    text = rng.choice(PRE) + (text if rng.random() < 0.7 else text.rstrip("\r\n"))
    kwargs = {
        "empty_as_nan": gaps_only or rng.random() < 0.6,
        "exact_integers": rng.choice([False, True, ["a"]]),
        "integer_offsets": rng.choice([(), ["time_s"], ["a", "b"]]),
    }
    return text, kwargs


def outcome(path, monkeypatch, fast, **kwargs):
    """A read's columns (floats bitwise: the sign of 0 and of NaN), dtypes and lines, or the
    error text."""
    try:
        (cols, lines), took = read(path, monkeypatch, fast, **kwargs)
    except ValueError as err:
        return f"ValueError: {err}", False
    out = [(k, v.dtype.str, (v.view(np.int64) if v.dtype.kind == "f" else v).tolist())
           for k, v in cols.items()]  # fmt: skip
    return repr((out, lines.dtype.str, lines.tolist())), took


def test_random_files_read_as_the_validating_reader(tmp_path, monkeypatch):
    """300 seeded random small files (gaps, comments, blank lines, rows of empty fields, odd
    numbers and blanks, CRLF, a BOM, no final newline) read with random keywords: the fast
    path, at chunks of one line, of a few lines and the default, gives exactly the validating
    reader's columns, dtypes and lines, or its error text; the fast path takes most."""
    import random

    rng = random.Random(20261130)
    path = tmp_path / "r.csv"
    took_count = 0
    for trial in range(300):
        text, kwargs = random_file(rng)
        path.write_bytes(text.encode())
        slow, _ = outcome(path, monkeypatch, False, **kwargs)
        for chunk in (1, 13, 1 << 18):
            monkeypatch.setattr(_csv_numeric, "CHUNK_BYTES", chunk)
            fast, took = outcome(path, monkeypatch, True, **kwargs)
            took_count += took
            assert fast == slow, (trial, chunk, kwargs, text)
    assert took_count > 300, took_count
