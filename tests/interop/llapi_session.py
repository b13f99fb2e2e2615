"""Runs docs/examples/python_llapi.py (or its mlagents_envs copy) once, with the stub pressing
Play in the "Editor" twice, and prints the example's last line (its JSON summary).

    python -m tests.interop.llapi_session PYTHON SCRIPT FOLDER

PYTHON runs SCRIPT in FOLDER (which holds the ``3DBall`` build); the stub runs under this
interpreter. tests/interop/test_llapi_example.py starts it in a network namespace of its own
where it can, so the page's fixed ports (5005 and the Editor's 5004) are free.
"""
from __future__ import annotations

import os
import subprocess
import sys
import time

from tests.stub.conftest import REPO, start_stub


def listener(port: int) -> str | None:
    """The inode of the socket listening on ``port`` (IPv4 or IPv6), read from /proc without
    connecting; None if nothing listens."""
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        with open(table) as f:
            for line in f.readlines()[1:]:
                fields = line.split()
                if fields[3] == "0A" and int(fields[1].rsplit(":", 1)[1], 16) == port:
                    return fields[9]
    return None


def press_play(example: subprocess.Popen, served: set[str], timeout: float = 180.0) -> None:
    """Start the stub as the Editor once the example listens on 5004 with a server not yet
    served (each of the page's two Editor snippets opens its own), and wait for the session to end."""
    deadline = time.monotonic() + timeout
    while (listener(5004) in served or listener(5004) is None) and example.poll() is None:
        if time.monotonic() > deadline:
            return  # the example's own error says why
        time.sleep(0.1)
    if example.poll() is not None:
        return
    served.add(listener(5004))
    editor = start_stub(5004, "basic", "--connect-timeout", "60")
    _, err = editor.communicate(timeout=timeout)
    if editor.returncode != 0:
        sys.exit(f"the stub playing the Editor failed:\n{err[-2000:]}")


def main(python: str, script: str, folder: str) -> None:
    env = dict(os.environ)
    if python == sys.executable:
        env["PYTHONPATH"] = REPO
    else:  # the real ML-Agents must never see our packages or our protobuf
        env.pop("PYTHONPATH", None)
    # output to files: mlagents_envs logs a warning per message with unknown side channel data,
    # which would fill a pipe nobody reads while the Editor is being played
    out_path, err_path = os.path.join(folder, "example.out"), os.path.join(folder, "example.err")
    with open(out_path, "w") as out, open(err_path, "w") as err:
        example = subprocess.Popen([python, script], cwd=folder, env=env, stdout=out, stderr=err)
        try:
            served: set[str] = set()
            for _ in range(2):  # snippets 2 and 3 wait for the Editor
                press_play(example, served)
            example.wait(timeout=180)
        finally:
            if example.poll() is None:
                example.kill()
                example.wait()
    if example.returncode != 0:
        with open(err_path) as f:
            sys.exit(f"the example failed:\n{f.read()[-3000:]}")
    with open(out_path) as f:
        print(f.read().strip().splitlines()[-1])


if __name__ == "__main__":
    main(*sys.argv[1:4])
