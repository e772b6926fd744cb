"""sumo-gui on a (virtual) screen: it starts, draws the road and the vehicles in their
colours, and without a display it fails at once with one line.

The screenshot test starts its own Xvfb (Debian package ``xvfb``; skipped only when
``Xvfb`` is not installed; CI installs it), runs sumo-gui through TraCI on the default
scenario's network and routes in a subprocess (``python tests/test_gui.py OUT_DIR``,
which prints ``RESULT <json>``), and reads the pictures back: a screenshot before any
vehicle entered shows only the road (a black band as wide as the 10.2 m road on a white
background); a later one shows each vehicle in view as a patch of its kind's colour
(CAVs blue 31,119,180, HDVs orange 255,127,14) where TraCI says the vehicle is.
"""

from __future__ import annotations

import json
import os
import select
import shutil
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from cosim.demand.routes import CAV_RGB, HDV_RGB

pytestmark = pytest.mark.gui

VIEW_X_M = (0.0, 250.0)  # stretch of road the screenshots show, m from the road's start
COLOUR_TOL = 40  # largest per-channel difference (0..255) still counted as a vehicle colour


# --------------------------------------------------------------------------------------
# Xvfb
# --------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def xvfb(tmp_path_factory):
    """A private Xvfb server (1280 x 800, 24 bit); yields its DISPLAY string, e.g. ``:3``.

    ``-displayfd`` lets Xvfb pick a free display number, so parallel runs do not clash.
    """
    exe = shutil.which("Xvfb")
    if exe is None:
        pytest.skip("Xvfb is not installed (Debian: apt-get install xvfb)")
    log = tmp_path_factory.mktemp("xvfb") / "xvfb.log"
    r, w = os.pipe()
    with log.open("wb") as out:
        proc = subprocess.Popen(
            [exe, "-displayfd", str(w), "-screen", "0", "1280x800x24", "-nolisten", "tcp"],
            pass_fds=(w,), stdout=out, stderr=subprocess.STDOUT,
        )
    os.close(w)
    try:
        number = b""
        end = time.monotonic() + 20.0
        while not number.endswith(b"\n") and time.monotonic() < end:
            ready, _, _ = select.select([r], [], [], 0.2)
            if ready:
                chunk = os.read(r, 16)
                if not chunk:
                    break
                number += chunk
        assert number.strip().isdigit(), f"Xvfb did not start: {log.read_text()[-1500:]}"
        yield f":{int(number)}"
    finally:
        os.close(r)
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def _with_display(display: str | None) -> dict:
    env = dict(os.environ)
    env.pop("DISPLAY", None)
    if display is not None:
        env["DISPLAY"] = display
    return env


# --------------------------------------------------------------------------------------
# Without a display: one line, at once
# --------------------------------------------------------------------------------------

# check_display() behind the CLI's error handler; prints the check's own duration, s
_CLI_CHECK = """
import sys, time
from cosim.cli.errors import run_command
from cosim.sumo.gui import check_display
t0 = time.monotonic()
rc = run_command(lambda ns: check_display() or 0, None)
print(f"ELAPSED {time.monotonic() - t0:.3f}")
sys.exit(rc)
"""


def _check_display_cli(env: dict) -> tuple[subprocess.CompletedProcess, float]:
    """Run _CLI_CHECK in a fresh interpreter; (result, seconds the check took)."""
    proc = subprocess.run([sys.executable, "-c", _CLI_CHECK], capture_output=True, text=True,
                          env=env, timeout=30, check=False)
    elapsed = [ln for ln in proc.stdout.splitlines() if ln.startswith("ELAPSED ")]
    assert elapsed, proc.stdout + proc.stderr
    return proc, float(elapsed[-1].split()[1])


def _free_display_number() -> int:
    """A display number with no X server: neither its local socket nor its TCP port answer."""
    for n in range(917, 999):
        if os.path.exists(f"/tmp/.X11-unix/X{n}"):
            continue
        with socket.socket(socket.AF_UNIX) as s:
            try:
                s.connect(f"\0/tmp/.X11-unix/X{n}")
                continue
            except OSError:
                return n
    raise AssertionError("no free display number in 917..998")


@pytest.mark.parametrize("display", [None, "", "dead", "nonsense"])
def test_no_display_fails_in_one_line_within_two_seconds(display):
    """DISPLAY unset, empty, naming a display no server answers on, or malformed: exit
    status 2 and exactly one stderr line ``error: --gui needs an X display...``, in under
    2 s (traci.start would retry for a minute)."""
    if display == "dead":
        display = f":{_free_display_number()}"
    proc, elapsed = _check_display_cli(_with_display(display))
    lines = proc.stderr.splitlines()
    assert proc.returncode == 2, proc.stderr
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith("error: --gui needs an X display, but ")
    assert "xvfb-run" in lines[0]
    if display:
        assert f"DISPLAY={display}" in lines[0] or f"DISPLAY={display!r}" in lines[0]
    assert elapsed < 2.0


def test_x_server_that_never_answers_fails_within_two_seconds():
    """Something accepts connections on the display's TCP port but never speaks X (a hung
    server, a dead ssh tunnel): the check gives up at its 1.5 s deadline."""
    with socket.socket() as listener:
        listener.bind(("127.0.0.1", 0))
        listener.listen(4)
        port = listener.getsockname()[1]
        if port <= 6000:
            pytest.fail(f"ephemeral port {port} cannot be written as a display number")
        proc, elapsed = _check_display_cli(_with_display(f"127.0.0.1:{port - 6000}"))
    lines = proc.stderr.splitlines()
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr
    assert "did not answer within 1.5 s" in lines[0]
    assert 1.4 < elapsed < 2.0


def test_live_display_passes_the_check(xvfb):
    proc, elapsed = _check_display_cli(_with_display(xvfb))
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr
    assert elapsed < 2.0


def test_gui_start_failure_is_one_line_with_sumo_guis_reason(xvfb, tmp_path):
    """sumo-gui refusing its input (here a missing network file) shows its error only in
    its window; start_gui reads it from sumo-gui's error log and fails at once."""
    code = (
        "import sys, time\n"
        "from cosim.cli.errors import run_command\n"
        "from cosim.sumo.gui import start_gui\n"
        "from cosim.sumo.binaries import sumo_binary\n"
        "t0 = time.monotonic()\n"
        f"cmd = [str(sumo_binary('sumo-gui')), '-n', {str(tmp_path / 'missing.net.xml')!r}]\n"
        "rc = run_command(lambda ns: start_gui(cmd) and 0, None)\n"
        "print(f'ELAPSED {time.monotonic() - t0:.3f}'); sys.exit(rc)\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env=_with_display(xvfb), timeout=60, check=False)
    lines = proc.stderr.splitlines()
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr
    assert lines[0].startswith("error: sumo-gui failed to start: ")
    assert "missing.net.xml' is not accessible" in lines[0]
    elapsed = float(proc.stdout.split("ELAPSED ")[-1])
    assert elapsed < 10.0


# --------------------------------------------------------------------------------------
# The screenshot: road and vehicles
# --------------------------------------------------------------------------------------


def _png_size(path: Path) -> tuple[int, int]:
    """(width, height) in pixels of a PNG file, from its header."""
    import struct

    return struct.unpack(">II", path.read_bytes()[16:24])


def _screenshot_case(out: Path) -> dict:
    """Run sumo-gui on the default scenario's network and routes; two screenshots.

    ``empty.png`` after the first step (no vehicle has entered yet), ``busy.png`` at the
    first step when at least two CAVs and two HDVs are wholly inside the view. Returns
    the view's boundary (m) and, for ``busy.png``, every vehicle in view: kind, front
    bumper (x, y) in m, length and width in m, angle in degrees (SUMO: 90 = +x).
    """
    from cosim.config.scenario import load_scenario
    from cosim.demand.routes import write_routes
    from cosim.road.build import build_network
    from cosim.sumo.binaries import sumo_binary
    from cosim.sumo.gui import DEFAULT_VIEW, screenshot, start_gui
    from cosim.sumo.sublanes import scenario_resolution_m

    sc = load_scenario("default")  # what `cosim run default` runs
    run = sc.scenario
    net = build_network(sc.network)
    duration_s = 150.0
    routes = write_routes(net, sc.demand, run.seed, out / "routes.rou.xml", horizon_s=duration_s)
    ts = start_gui([
        str(sumo_binary("sumo-gui")), "-n", str(net.net_file), "-r", str(routes.path),
        "--step-length", str(run.step_length_s), "--seed", str(run.seed),
        "--lateral-resolution", f"{scenario_resolution_m(sc, net):g}",
        "--begin", "0", "--end", str(duration_s), "--collision.action", "none",
        "--no-step-log", "true", "--no-warnings", "true", "--window-size", "1280,800",
    ])
    try:
        ts.gui.setBoundary(DEFAULT_VIEW, VIEW_X_M[0], -30.0, VIEW_X_M[1], 30.0)
        res = {"road_width_m": sc.network.width_m}
        for _ in range(5):  # a loaded machine may lay the window out after the first
            screenshot(ts, out / "empty.png")  # picture (seen: a 1 x 1 pixel one): again
            if _png_size(out / "empty.png")[1] >= 100 or ts.vehicle.getIDCount():
                break
        # the view as drawn: read after the picture (a loaded machine may lay out the
        # window after the boundary was asked for, and sumo-gui then fits it again)
        res["boundary"] = ts.gui.getBoundary(DEFAULT_VIEW)
        res["vehicles_at_empty"] = ts.vehicle.getIDCount()
        res["t_empty_s"] = ts.simulation.getTime()
        (x0, _), (x1, _) = res["boundary"]
        while ts.simulation.getTime() < duration_s - 1.0:
            vehs = []
            for vid in ts.vehicle.getIDList():
                x, y = ts.vehicle.getPosition(vid)
                length = ts.vehicle.getLength(vid)
                if x0 + 2.0 < x - length and x < x1 - 2.0:
                    vehs.append({
                        "kind": ts.vehicle.getTypeID(vid).split("_")[0], "x": x, "y": y,
                        "length": length, "width": ts.vehicle.getWidth(vid),
                        "angle": ts.vehicle.getAngle(vid),
                    })
            kinds = [v["kind"] for v in vehs]
            if kinds.count("cav") >= 2 and kinds.count("hdv") >= 2:
                break
            ts.simulationStep()
        # sumo-gui draws the screenshot at the end of the next step: record after it
        ts.gui.screenshot(DEFAULT_VIEW, str((out / "busy.png").resolve()))
        ts.simulationStep()
        res["t_busy_s"] = ts.simulation.getTime()
        res["vehicles"] = []
        for vid in ts.vehicle.getIDList():
            x, y = ts.vehicle.getPosition(vid)
            if x0 < x and x - ts.vehicle.getLength(vid) < x1:
                res["vehicles"].append({
                    "kind": ts.vehicle.getTypeID(vid).split("_")[0], "x": x, "y": y,
                    "length": ts.vehicle.getLength(vid), "width": ts.vehicle.getWidth(vid),
                    "angle": ts.vehicle.getAngle(vid),
                })
    finally:
        ts.close()
    return res


@pytest.fixture(scope="module")
def shots(xvfb, tmp_path_factory) -> dict:
    out = tmp_path_factory.mktemp("gui")
    env = _with_display(xvfb)
    env["COSIM_NETWORK_CACHE"] = str(tmp_path_factory.mktemp("network_cache"))
    proc = subprocess.run([sys.executable, __file__, str(out)], capture_output=True,
                          text=True, env=env, timeout=300, check=False)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    assert lines, proc.stdout[-2000:] + proc.stderr[-2000:]
    res = json.loads(lines[-1][len("RESULT "):])
    res["dir"] = out
    return res


def _rgb(path: Path) -> np.ndarray:
    from PIL import Image  # pillow comes with matplotlib

    with Image.open(path) as im:
        return np.asarray(im.convert("RGB")).astype(np.int16)


def _near(img: np.ndarray, rgb: tuple[int, int, int]) -> np.ndarray:
    """(H, W) bool: pixels within COLOUR_TOL of ``rgb`` in every channel."""
    return (np.abs(img - np.asarray(rgb, dtype=np.int16)) <= COLOUR_TOL).all(axis=2)


def _to_pixels(shots: dict, img: np.ndarray):
    """World (x, y) in m -> (column, row) in pixels of ``img`` (SUMO's y points up)."""
    (x0, y0), (x1, y1) = shots["boundary"]
    h, w = img.shape[:2]
    sx, sy = w / (x1 - x0), h / (y1 - y0)
    assert sx == pytest.approx(sy, rel=0.02), "the view is not drawn at one scale"
    return lambda x, y: ((np.asarray(x) - x0) * sx, (y1 - np.asarray(y)) * sy), sx


def _road_rows(img: np.ndarray) -> np.ndarray:
    """Rows that are at least 90 % dark (all channels < 60): the road's band."""
    dark = (img < 60).all(axis=2)
    return np.flatnonzero(dark.mean(axis=1) >= 0.9)


def test_empty_view_shows_the_road_and_no_vehicle(shots):
    """Before any vehicle entered: one contiguous black band across the whole picture,
    as high as the road is wide (10.2 m), centred where the road is (y = 0 m); the
    rest is background; not one pixel in a vehicle colour."""
    assert shots["vehicles_at_empty"] == 0 and shots["t_empty_s"] < 1.0
    img = _rgb(shots["dir"] / "empty.png")
    assert img.shape[0] >= 300 and img.shape[1] >= 600, img.shape
    to_px, px_per_m = _to_pixels(shots, img)
    rows = _road_rows(img)
    assert rows.size > 0, "no road in the picture"
    assert np.all(np.diff(rows) == 1), f"road rows not contiguous: {rows}"
    height_m = rows.size / px_per_m
    assert height_m == pytest.approx(shots["road_width_m"], abs=1.0)
    _, row_centre = to_px(0.0, 0.0)
    assert abs(rows.mean() - row_centre) < 0.5 * px_per_m  # within 0.5 m of y = 0
    above = img[: max(rows[0] - int(2 * px_per_m), 0)]  # 2 m off the road and up
    background = np.unique(above.reshape(-1, 3), axis=0, return_counts=True)
    share = background[1].max() / above.shape[0] / above.shape[1]
    assert share > 0.99, "the view above the road is not plain background"
    assert not _near(img, CAV_RGB).any() and not _near(img, HDV_RGB).any()


def test_vehicles_drawn_in_their_kinds_colour_where_traci_puts_them(shots):
    """In the busy picture every vehicle in view is a patch of its kind's colour inside
    its body's box (front bumper from TraCI, length back along +x, width across, 0.5 m
    margin): at least 20 % of the box (SUMO draws a car's outline, not a full box);
    and almost every pixel of each colour lies inside a box of that kind, so the blue
    ones are CAVs and the orange ones HDVs."""
    vehs = shots["vehicles"]
    kinds = [v["kind"] for v in vehs]
    assert kinds.count("cav") >= 2 and kinds.count("hdv") >= 2, (shots["t_busy_s"], kinds)
    img = _rgb(shots["dir"] / "busy.png")
    to_px, px_per_m = _to_pixels(shots, img)
    h, w = img.shape[:2]
    masks = {"cav": _near(img, CAV_RGB), "hdv": _near(img, HDV_RGB)}
    inside = {k: np.zeros((h, w), bool) for k in masks}
    margin = 0.5
    for v in vehs:
        assert abs(v["angle"] - 90.0) < 10.0  # heading along +x on the straight road
        (c0, c1), (r0, r1) = to_px(
            [v["x"] - v["length"] - margin, v["x"] + margin],
            [v["y"] + v["width"] / 2 + margin, v["y"] - v["width"] / 2 - margin],
        )
        c0, c1 = max(int(np.floor(c0)), 0), min(int(np.ceil(c1)), w)
        r0, r1 = max(int(np.floor(r0)), 0), min(int(np.ceil(r1)), h)
        inside[v["kind"]][r0:r1, c0:c1] = True
        body_px = v["length"] * v["width"] * px_per_m**2
        own = int(masks[v["kind"]][r0:r1, c0:c1].sum())
        assert own >= 0.2 * body_px, (v, own, body_px)
    for kind, mask in masks.items():
        n = int(mask.sum())
        assert n > 0
        assert (mask & inside[kind]).sum() >= 0.95 * n, f"{kind} colour outside {kind} boxes"
    # and the picture differs from the empty view exactly there: vehicles, not noise
    empty = _rgb(shots["dir"] / "empty.png")
    changed = (np.abs(img - empty) > COLOUR_TOL).any(axis=2)
    boxes = inside["cav"] | inside["hdv"]
    assert changed.sum() > 0.5 * (masks["cav"].sum() + masks["hdv"].sum())
    assert (changed & ~boxes).sum() <= 0.02 * changed.sum()


if __name__ == "__main__":
    # python tests/test_gui.py OUT_DIR: the sumo-gui case, run in its own process
    print("RESULT " + json.dumps(_screenshot_case(Path(sys.argv[1]))))
