#!/usr/bin/env python3
"""Pseudo-terminal relay for the emulator harness (standard library only).

Opens a pty pair in raw mode, prints `PTY <slave path>` on stderr, then relays bytes:
stdin -> pty master (the device's output, read by the host on the slave) and
pty master -> stdout (what the host writes on the slave, for the device).
It keeps its own handle on the slave open, so the host may close and reopen the port
(a disconnect and reconnect) without the master seeing a hang-up. Exits when stdin closes.
"""
import os
import select
import sys
import tty


def main():
    master, slave = os.openpty()
    tty.setraw(slave)
    tty.setraw(master)
    os.set_blocking(master, False)
    sys.stderr.write("PTY %s\n" % os.ttyname(slave))
    sys.stderr.flush()
    stdin, stdout = sys.stdin.fileno(), sys.stdout.fileno()
    while True:
        readable, _, _ = select.select([stdin, master], [], [])
        if stdin in readable:
            data = os.read(stdin, 4096)
            if not data:
                return 0
            try:
                n = os.write(master, data)
                if n < len(data):
                    raise BlockingIOError
            except BlockingIOError:
                # Nobody reads the port and its buffer is full: drop, as a link would.
                sys.stderr.write("DROPPED %d\n" % len(data))
                sys.stderr.flush()
        if master in readable:
            try:
                data = os.read(master, 4096)
            except (BlockingIOError, OSError):
                data = b""
            if data:
                os.write(stdout, data)


if __name__ == "__main__":
    sys.exit(main())
