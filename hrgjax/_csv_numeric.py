"""The fast path of `hrgjax._data_files.read_csv_table`: a plain numeric CSV file streamed
through NumPy's C parser in chunks of lines (`numeric_rows`), with no Python string per
field and no copy of the whole text.

A chunk (about `CHUNK_BYTES` of whole lines) is checked at once: only the characters of
numbers (digits, `.eE+-`, `nan`, `inf`, `infinity` in any case), commas and blanks, no
quote, no lone carriage return, no line longer than the csv module's field limit. A chunk
that also has no blank line, no comment and no empty field goes to NumPy as it is, its rows
numbered by a range; so does one whose every line holds a number, with empty fields but
no blank or tab, once each empty field is made `nan` where asked (the separators side by
side found by NumPy, the `nan` inserted in one `np.insert`: a log with a gap in every row). Any other chunk is read line by line (comments and blank lines
skipped, a row of empty fields held until a sample follows it, an empty field read as NaN
where asked). Whatever this path cannot read as the validating reader would, it leaves to
that reader (None), which reads the file and names what is wrong."""

from __future__ import annotations

import array
import itertools
import os
import warnings

import numpy as np

from ._progress import bar

CHUNK_BYTES = 1 << 18
"""Bytes of whole lines examined at a time."""
FIELD_LIMIT = 131072
"""The csv module's field limit, which the validating reader reports: a longer line is left
to it."""
PROGRESS_LINES = 10**6
"""A read of more lines shows a progress bar (stderr, at a terminal)."""

_ALPHABET = b"0123456789.eE+-nNaAiIfFtTyY, \t\r\n"
"""Every byte a numeric data line may hold (a field NumPy parses over these is one
`is_number` accepts: tests/test_files.py)."""
_BLANKS = b" \t\r"
_BOM = b"\xef\xbb\xbf"
CLEAN, GAPS, OTHER = 0, 1, 2
"""A chunk's form (`_Lines._form`): samples as they are; samples with empty fields (no blank
or tab, no line without a number); anything else (read line by line)."""


_NAN = np.frombuffer(b"nan", dtype=np.uint8)


def _fill(blob: bytes, at: np.ndarray) -> bytes:
    """`blob` with `nan` inserted at each offset `at` (its empty fields: `_Lines._form`)."""
    code = np.frombuffer(blob, dtype=np.uint8)
    return np.insert(code, np.repeat(at, _NAN.size), np.tile(_NAN, at.size)).tobytes()


class _Lines:
    """The data lines of one file, as the str lines NumPy reads (`chunks`), with each one's
    line in the file (`lines`); `bad` once a line is not plain numeric (then nothing more is
    read)."""

    def __init__(self, fh, size: int, empty_as_nan: bool, desc: str):
        self.fh, self.size, self.empty_as_nan, self.desc = fh, size, empty_as_nan, desc
        self.lines = array.array("q")
        self.longest = 0  # bytes of the longest data line
        self.header: list[str] | None = None
        self.header_line = 0
        self.bad = False
        self.at = 0  # the file's lines read so far
        self.done = 0  # the file's bytes read so far
        self.pending: list[tuple[int, int]] = []  # rows of empty fields: (line, fields)
        self.progress = None
        self.shown_mb = 0

    def chunks(self):
        """The data lines, a list of str lines at a time (`itertools.chain` hands NumPy one
        line at a time with no Python call per line)."""
        try:
            if self._read_header():
                yield from self._data()
        finally:
            if self.progress is not None:
                self.progress.close()

    def _read_header(self) -> bool:
        for raw in self.fh:
            self.at += 1
            self.done += len(raw)
            if self.at == 1:
                raw = raw.removeprefix(_BOM)
            if not self._plain(raw, len(raw)):
                return False
            try:
                text = raw.decode("utf-8")
            except UnicodeDecodeError:
                return self._refuse()
            stripped = text.strip()  # (all Unicode whitespace, as the validating reader)
            if not stripped or stripped.startswith("#"):
                continue
            self.header = [h.strip() for h in text.rstrip("\r\n").split(",")]
            self.header_line = self.at
            return True
        return False

    def _refuse(self) -> bool:
        self.bad = True
        return False

    def _plain(self, blob: bytes, longest: int) -> bool:
        """No quote, no lone carriage return, no line (of `longest` bytes) beyond the field
        limit; else refused."""
        if b'"' in blob or (b"\r" in blob and blob.count(b"\r") != blob.count(b"\r\n")):
            return self._refuse()
        return longest <= FIELD_LIMIT or self._refuse()

    def _data(self):
        while True:
            chunk = self.fh.readlines(CHUNK_BYTES)
            if not chunk:
                if self.progress is not None:  # (the bar shows whole MB: the last part)
                    self.progress.update(self.progress.total - self.shown_mb)
                return
            blob = b"".join(chunk)
            longest = max(map(len, chunk))
            if not self._plain(blob, longest):
                return
            self.longest = max(self.longest, longest)
            first = self.at + 1
            self.at += len(chunk)
            self.done += len(blob)
            form, empty = (OTHER, None) if blob.translate(None, _ALPHABET) else self._form(blob)
            if form == GAPS and self.empty_as_nan:
                blob = _fill(blob, empty)
            if form == CLEAN or (form == GAPS and self.empty_as_nan):
                out = self._flush()  # (rows of empty fields that a sample follows)
                self.lines.frombytes(np.arange(first, self.at + 1, dtype=np.int64).tobytes())
                out += blob.decode("ascii").splitlines(keepends=True)
            else:
                out = []
                for i, raw in enumerate(chunk, first):
                    self._line(raw, i, out)
                    if self.bad:
                        break
            if self.bad:
                return
            yield out
            self._show()

    @staticmethod
    def _form(blob: bytes) -> tuple[int, np.ndarray | None]:
        """`CLEAN` where every line of `blob` (numeric characters only) holds a sample with no
        empty field: no blank line, no field of blanks (no two separators side by side once
        the blanks are out; a bytes search for them is slow where commas are frequent);
        `GAPS` where the only fault is empty fields, with no blank or tab in the chunk (so
        none is a field of blanks) and a number on every line (no blank line, no row of empty
        fields), with the offset in `blob` of each empty field; else `OTHER`."""
        spaced = b" " in blob or b"\t" in blob
        tight = blob.translate(None, _BLANKS) if spaced or b"\r" in blob else blob
        if not tight:
            return OTHER, None
        code = np.frombuffer(tight, dtype=np.uint8)
        sep = (code == ord(",")) | (code == ord("\n"))
        ends = blob.endswith(b"\n")  # (else the last line's end is the file's: no separator)
        side_by_side = sep[1:] & sep[:-1]
        if not (sep[0] or (not ends and sep[-1]) or np.any(side_by_side)):
            return CLEAN, None
        if spaced:
            return OTHER, None
        bare = tight.translate(None, b",")  # a line with no number is an empty line here
        if not bare or bare[:1] == b"\n" or b"\n\n" in bare or (not ends and bare[-1:] == b"\n"):
            return OTHER, None
        at = np.flatnonzero(side_by_side) + 1  # (between two separators)
        if sep[0]:
            at = np.insert(at, 0, 0)
        if not ends and sep[-1]:
            at = np.append(at, code.size)
        if len(tight) != len(blob):  # (each carriage return before it shifts it by one)
            cr = np.flatnonzero(np.frombuffer(blob, dtype=np.uint8) == ord("\r"))
            at += np.searchsorted(cr - np.arange(cr.size), at)  # (a CR's offset in `tight`)
        return GAPS, at

    def _line(self, raw: bytes, i: int, out: list[str]) -> None:
        """One line read on its own, onto `out` as the str line NumPy reads (nothing for a
        comment, a blank line, a row of empty fields held back, or a line refused)."""
        stripped = raw.strip(b" \t\r\n")
        if not stripped:
            return  # a blank line
        if stripped[:1] == b"#":
            try:
                raw.decode("utf-8")  # (the validating reader refuses text that is not UTF-8)
            except UnicodeDecodeError:
                self.bad = True
            return
        if raw.translate(None, _ALPHABET):
            self.bad = True
            return
        fields = stripped.split(b",")
        empty = [not f.strip(b" \t") for f in fields]
        if all(empty):  # a missing sample, or a spreadsheet's trailing rows: known later
            self.pending.append((i, len(fields)))
            return
        if any(empty):
            if not self.empty_as_nan:
                self.bad = True
                return
            raw = b",".join(b"nan" if e else f for f, e in zip(fields, empty, strict=True))
            raw += b"\n"
        out += self._flush()
        self.lines.append(i)
        out.append(raw.decode("ascii"))

    def _flush(self) -> list[str]:
        """The rows of empty fields before a sample, as rows of NaN where `empty_as_nan` asks
        (else, or for another number of fields than the header's, refused: `bad`)."""
        if not self.pending:
            return []
        ncol = len(self.header or ())
        if not self.empty_as_nan or any(n != ncol for _, n in self.pending):
            self.bad = True
            return []
        self.lines.extend(i for i, _ in self.pending)
        rows = [",".join(["nan"] * ncol) + "\n"] * len(self.pending)
        self.pending.clear()
        return rows

    def _show(self):
        """The progress bar, in whole MB of the file, from the first chunk on where the file
        holds more than `PROGRESS_LINES` lines at the bytes a line read so far."""
        if self.progress is None:
            if self.at * self.size <= PROGRESS_LINES * max(self.done, 1):
                return
            self.progress = bar(-(-self.size // 10**6), self.desc, unit="MB")
        mb = self.done // 10**6
        self.progress.update(mb - self.shown_mb)
        self.shown_mb = mb


def numeric_rows(path: str, empty_as_nan: bool = False):
    """`(header, header_line, values, lines, longest)` of a plain numeric CSV file (module
    notes): the header's stripped fields and its line, the samples as an `(n, fields)`
    float64 array (an empty field NaN with `empty_as_nan`, a row of empty fields before a
    sample a row of NaN; rows of empty fields after the last sample dropped), the file's line
    of each row and the bytes of the longest data line (an integer that a float64 rounds to
    inf has 309 digits or more); None for a file this path leaves to the validating reader."""
    with open(path, "rb") as fh, warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # "input contained no data": read again
        size = os.fstat(fh.fileno()).st_size
        rows = _Lines(fh, size, empty_as_nan, f"reading {os.path.basename(path)}")
        chunks = rows.chunks()
        try:
            values = np.loadtxt(itertools.chain.from_iterable(chunks), delimiter=",",
                                dtype=float, ndmin=2, comments=None)  # fmt: skip
        except ValueError:  # a field NumPy does not take, or another number of fields
            return None
        finally:
            chunks.close()  # (the progress bar with it)
    if rows.bad or rows.header is None or not rows.lines:
        return None
    if values.shape != (len(rows.lines), len(rows.header)):
        return None
    lines = np.frombuffer(rows.lines, dtype=np.int64).copy()
    return rows.header, rows.header_line, values, lines, rows.longest
