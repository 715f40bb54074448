"""The GIL is released while smoothing, and Ctrl-C stops a long call within a second, leaving
no partial output file."""

import signal
import subprocess
import sys
import textwrap
import threading
import time

import numpy as np
import pytest

import vcsmooth


def test_other_threads_run_while_smoothing(kitten):
    v, f = kitten
    start = time.perf_counter()
    vcsmooth.smooth(v, f, iterations=5)
    per_iteration = (time.perf_counter() - start) / 5
    # About two seconds of smoothing in a thread; this one keeps ticking meanwhile.
    iterations = max(10, int(2.0 / per_iteration))
    worker = threading.Thread(target=vcsmooth.smooth, args=(v, f), kwargs=dict(iterations=iterations))
    ticks = []
    worker.start()
    while worker.is_alive():
        ticks.append(time.perf_counter())
        time.sleep(0.005)
    worker.join()
    gaps = np.diff(ticks)
    assert len(ticks) > 50, len(ticks)
    assert gaps.max() < 0.5, gaps.max()


SCRIPT = textwrap.dedent(
    """
    import sys, vcsmooth
    kind, source, output = sys.argv[1:]
    print("started", flush=True)
    if kind == "file":
        vcsmooth.smooth_file(source, output, iterations=10**6, progress=True)
    else:
        v, f = vcsmooth.read_mesh(source)
        vcsmooth.smooth(v, f, iterations=10**6)
    """
)


@pytest.mark.parametrize("kind", ["file", "arrays"])
def test_ctrl_c_stops_a_long_call(tmp_path, kitten_path, kind):
    output = tmp_path / "out.ply"
    output.write_bytes(b"the previous output")
    proc = subprocess.Popen(
        [sys.executable, "-c", SCRIPT, kind, str(kitten_path), str(output)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout.readline().strip() == "started"
        if kind == "file":
            # Wait until it is iterating (its progress lines).
            line = proc.stderr.readline()
            assert "iteration 1/" in line, line
        else:
            time.sleep(1.0)
        assert proc.poll() is None
        proc.send_signal(signal.SIGINT)
        sent = time.perf_counter()
        _, err = proc.communicate(timeout=30)
        elapsed = time.perf_counter() - sent
    finally:
        if proc.poll() is None:
            proc.kill()
    assert "KeyboardInterrupt" in err, err[-2000:]
    assert elapsed < 1.0, elapsed
    # The previous output untouched, no temporary file beside it.
    assert output.read_bytes() == b"the previous output"
    assert [p.name for p in tmp_path.iterdir()] == ["out.ply"]
