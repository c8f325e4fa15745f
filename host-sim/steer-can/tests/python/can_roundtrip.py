"""steer-can's candump files against python-can's own reader and writer (CanutilsLogReader,
CanutilsLogWriter), both ways:

1. a recording of the simulated car (`steer-can --iface sim record`) reads in python-can as
   the same frames, on interface can0, every line;
2. python-can writes those frames back (its lines end in ` R`), and `steer-can convert` makes
   of that file the very log it makes of its own recording.

Run by .ci/run (which installs python-can) as `python3 can_roundtrip.py STEER_CAN_EXE`.
"""

import pathlib
import shutil
import subprocess
import sys
import tempfile

import can


def run(*args):
    done = subprocess.run(args, capture_output=True, text=True, stdin=subprocess.DEVNULL)
    if done.returncode != 0:
        sys.exit(f"{' '.join(map(str, args))}: exit {done.returncode}\n{done.stderr}")
    return done


def main():
    exe = sys.argv[1]
    tmp = pathlib.Path(tempfile.mkdtemp())
    ours = tmp / "bus.candump"
    run(exe, "--iface", "sim", "--fast", "record", "--out", ours, "--duration-s", "3")
    lines = [l for l in ours.read_text().splitlines() if l.strip()]

    read = list(can.CanutilsLogReader(ours))
    checks = []
    checks.append((len(read) == len(lines), f"python-can read {len(read)} of {len(lines)} lines"))
    channels = {m.channel for m in read}
    checks.append((channels == {"can0"}, f"channels {channels}"))
    references = [m for m in read if m.arbitration_id == 0x100]
    # 0.3 s Ready + 2.01 s of sine + 0.2 s Finished + 0.2 s Off, one frame per 10 ms.
    checks.append((len(references) == 271, f"{len(references)} reference frames"))
    checks.append((all(m.dlc == 8 for m in references), "reference frames of 8 bytes"))
    # Each line's frame, as python-can read it, is the line's own.
    for line, m in zip(lines, read):
        body = line.split()[2]
        want_id, want_data = body.split("#")
        if int(want_id, 16) != m.arbitration_id or bytes.fromhex(want_data) != bytes(m.data):
            checks.append((False, f"`{line}` read as {m}"))
            break

    theirs = tmp / "python-can.log"
    with can.CanutilsLogWriter(theirs) as w:
        for m in read:
            w.on_message_received(m)
    first = theirs.read_text().splitlines()[0]
    checks.append((first.endswith(" R"), f"python-can's line `{first}` ends in ` R`"))

    log_ours, log_theirs = tmp / "ours.csv", tmp / "theirs.csv"
    run(exe, "convert", ours, "--out", log_ours)
    run(exe, "convert", theirs, "--out", log_theirs)
    same = log_ours.read_bytes() == log_theirs.read_bytes()
    rows = len(log_ours.read_text().splitlines())
    checks.append((same, "the log of python-can's file is the log of steer-can's"))
    checks.append((rows > 200, f"{rows} lines in the log"))

    # can-utils' log2asc converts only the interfaces it is given: the car's `can0` is enough.
    if shutil.which("log2asc"):
        asc = tmp / "bus.asc"
        run("log2asc", "-I", ours, "-O", asc, "can0")
        frames = [l for l in asc.read_text().splitlines() if l[:1] == " " and " Rx " in l]
        checks.append((len(frames) == len(lines), f"log2asc wrote {len(frames)} of {len(lines)} frames"))
    else:
        print("log2asc not installed: not checked")

    failed = [why for ok, why in checks if not ok]
    for ok, why in checks:
        print(("ok   " if ok else "FAIL ") + why)
    print(f"{len(checks) - len(failed)} passed, {len(failed)} failed")
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
