"""The longest silence of a command on a terminal: run it under a pseudo-terminal (so
progress bars draw, as for a person), time-stamp every write, and print the longest gap
between two writes, where it began, the wall time and the exit status.

    .venv/bin/python benchmarks/silence.py -- hrgjax allan log.csv --column rate --fit
    .venv/bin/python benchmarks/silence.py --log out/silence.log -- python my_study.py

The developers' rule is that nothing sits silent for more than a few seconds (docs/speed.md,
"Work that sat silent", measured with this; the terminal is 120 × 40, a size tqdm draws in).
POSIX only (`pty`)."""

from __future__ import annotations

import argparse
import fcntl
import os
import pty
import select
import struct
import sys
import termios
import time


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--log", default=None, help="write the time-stamped output here")
    p.add_argument("command", nargs=argparse.REMAINDER, help="-- then the command")
    args = p.parse_args()
    cmd = args.command[1:] if args.command[:1] == ["--"] else args.command
    if not cmd:
        p.error("give the command after --")
    pid, fd = pty.fork()
    if pid == 0:
        os.execvp(cmd[0], cmd)
    fcntl.ioctl(fd, termios.TIOCSWINSZ, struct.pack("HHHH", 40, 120, 0, 0))
    t0 = last = time.monotonic()
    longest, at = 0.0, 0.0
    log = open(args.log, "wb") if args.log else None  # noqa: SIM115
    while True:
        try:
            ready, _, _ = select.select([fd], [], [], 1.0)
            if not ready:
                continue
            data = os.read(fd, 65536)
        except OSError:  # the child closed the terminal
            break
        if not data:
            break
        now = time.monotonic()
        if now - last > longest:
            longest, at = now - last, last - t0
        last = now
        if log is not None:
            log.write(f"[{now - t0:8.2f}] ".encode() + data.replace(b"\r", b"\\r") + b"\n")
    _, status = os.waitpid(pid, 0)
    end = time.monotonic()
    if end - last > longest:
        longest, at = end - last, last - t0
    if log is not None:
        log.close()
    print(f"exit {os.waitstatus_to_exitcode(status)}, wall {end - t0:.1f} s, longest silence "
          f"{longest:.1f} s from t = {at:.1f} s", file=sys.stderr)  # fmt: skip


if __name__ == "__main__":
    main()
