"""sumo-gui: check the X display first, start sumo-gui through TraCI, take screenshots.

``cosim run NAME --gui`` runs the simulation in sumo-gui (through TraCI instead of
libsumo). Without a usable display sumo-gui exits at once, and ``traci.start`` then
retries for a minute with about 250 lines of output before it fails. :func:`check_display`
finds out first, in well under two seconds, and raises :class:`SumoStartError` with one
line. :func:`start_gui` does that check, starts sumo-gui so that it runs without a click
(``--start``) and quits when the connection closes (``--quit-on-end``), and turns a failed
start into one line that quotes sumo-gui's own error.

A machine without a screen can run the GUI under Xvfb (Debian package ``xvfb``):
``xvfb-run -a cosim run default --gui``.

In the view, CAVs are blue and HDVs orange (``cosim.demand.routes.CAV_RGB`` and
``HDV_RGB``, the colours of the figures); the road is black on a white background.
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from cosim.errors import SumoStartError

DEFAULT_VIEW = "View #0"  # sumo-gui's first (and usually only) view
CHECK_TIMEOUT_S = 1.5  # time the whole display check may take, s
START_RETRIES = 30  # TraCI connection attempts, 1 s apart, while sumo-gui loads the network
# sumo-gui view settings: the standard scheme, but vehicles drawn as car shapes (windows,
# outline) in their type's colour rather than as triangles
VIEW_SETTINGS_XML = """<viewsettings>
    <scheme name="cosim">
        <vehicles vehicleQuality="2" vehicle_minSize="1" vehicle_exaggeration="1"/>
    </scheme>
</viewsettings>
"""
_XSOCKET_DIR = "/tmp/.X11-unix"
_XTCP_PORT0 = 6000  # X display N listens on TCP port 6000 + N

# Opens the display named by $DISPLAY with Xlib, as sumo-gui does (this also checks X
# authorisation); exit 0: opened, 3: refused, 4: libX11 not loadable (cannot tell).
_XLIB_PROBE = """
import ctypes, ctypes.util, sys
try:
    x = ctypes.CDLL("libX11.so.6")
except OSError:
    name = ctypes.util.find_library("X11")
    if name is None:
        sys.exit(4)
    x = ctypes.CDLL(name)
x.XOpenDisplay.restype = ctypes.c_void_p
x.XOpenDisplay.argtypes = [ctypes.c_char_p]
sys.exit(0 if x.XOpenDisplay(None) else 3)
"""


def _fail(why: str) -> SumoStartError:
    return SumoStartError(
        f"--gui needs an X display, but {why}; on a machine without a screen, run under "
        "Xvfb, e.g. 'xvfb-run -a cosim run default --gui'"
    )


def _socket_addresses(display: str) -> list[tuple[int, object, str]]:
    """Where the X server of ``display`` listens: (family, address, description) triples.

    ``:N`` and ``unix:N`` are the local sockets (Linux abstract ``@/tmp/.X11-unix/XN``
    and the file ``/tmp/.X11-unix/XN``); ``HOST:N`` is TCP port 6000 + N on HOST;
    ``/path/to/socket:N`` (XQuartz) is that socket file.
    """
    m = re.fullmatch(r"(?P<host>.*):(?P<num>\d+)(?:\.\d+)?", display)
    if m is None:
        raise _fail(f"DISPLAY={display!r} is not of the form [HOST]:NUMBER[.SCREEN]")
    host, num = m["host"], int(m["num"])
    if host.startswith("/"):
        return [(socket.AF_UNIX, f"{host}:{num}", f"socket {host}:{num}")]
    if host in ("", "unix"):
        path = f"{_XSOCKET_DIR}/X{num}"
        out = [(socket.AF_UNIX, path, f"socket {path}")]
        if sys.platform.startswith("linux"):
            out.insert(0, (socket.AF_UNIX, "\0" + path, f"socket @{path}"))
        return out
    host = host.strip("[]")  # [::1]:0
    return [(socket.AF_UNSPEC, (host, _XTCP_PORT0 + num), f"{host} port {_XTCP_PORT0 + num}")]


def _connects(family: int, address: object, timeout_s: float) -> str | None:
    """None when something accepts a connection at ``address``, else the reason."""
    try:
        if family == socket.AF_UNSPEC:
            with socket.create_connection(address, timeout=max(timeout_s, 0.05)):
                return None
        with socket.socket(family, socket.SOCK_STREAM) as s:
            s.settimeout(max(timeout_s, 0.05))
            s.connect(address)
            return None
    except OSError as exc:
        return exc.strerror or str(exc) or type(exc).__name__


def check_display(timeout_s: float = CHECK_TIMEOUT_S) -> None:
    """Raise SumoStartError (one line) unless an X server answers on ``$DISPLAY``.

    Three steps, all within ``timeout_s`` seconds: ``DISPLAY`` is set and well formed;
    something accepts a connection on the display's socket (local socket or TCP port
    6000 + N); Xlib's ``XOpenDisplay`` succeeds on it (X authorisation included), tried
    in a subprocess that is killed at the deadline. Without libX11 the last step is
    skipped (sumo-gui then fails to start and :func:`start_gui` reports why).
    """
    deadline = time.monotonic() + timeout_s
    display = os.environ.get("DISPLAY", "").strip()
    if not display:
        raise _fail("DISPLAY is not set")
    reasons = []
    for family, address, what in _socket_addresses(display):
        why = _connects(family, address, deadline - time.monotonic())
        if why is None:
            break
        reasons.append(f"{what}: {why}")
    else:
        raise _fail(f"no X server answers on DISPLAY={display} ({'; '.join(reasons)})")
    try:
        proc = subprocess.run(
            [sys.executable, "-c", _XLIB_PROBE], capture_output=True, text=True,
            timeout=max(deadline - time.monotonic(), 0.1), check=False,
        )
    except subprocess.TimeoutExpired:
        raise _fail(
            f"the X server on DISPLAY={display} did not answer within {timeout_s:g} s"
        ) from None
    if proc.returncode in (0, 4):
        return
    said = " ".join(proc.stderr.split())[:200]
    raise _fail(
        f"the X server on DISPLAY={display} refused the connection"
        + (f" ({said})" if said else " (X authorisation? check XAUTHORITY)")
    )


def _gui_errors(*logs: Path) -> str:
    """sumo-gui's own error lines from its log files, folded into one line."""
    lines = []
    for log in logs:
        with contextlib.suppress(OSError):
            lines += [x.strip() for x in log.read_text(errors="replace").splitlines()]
    lines = [x for x in lines
             if x and not x.startswith(("Fontconfig", "Quitting (on error)"))]
    keep = [x for x in lines if "error" in x.lower() or "unable" in x.lower()] or lines[-2:]
    return " ".join(x.removeprefix("Error:").strip() for x in keep)[:400]


def start_gui(cmd: list[str], *, delay_ms: float = 0.0, quit_on_end: bool = True,
              view_settings: bool = True, retries: int = START_RETRIES):
    """Check the display, start sumo-gui with ``cmd`` and connect TraCI; return ``traci``.

    Args:
        cmd: sumo-gui command line (binary first), without ``--remote-port``.
        delay_ms: sumo-gui's ``--delay`` between steps, ms (0: as fast as it can draw).
        quit_on_end: close the window when the connection closes (``--quit-on-end``);
            False leaves it open and ``traci.close()`` then waits until the user closes it.
        view_settings: load :data:`VIEW_SETTINGS_XML` (``-g``; leave False if ``cmd``
            has its own ``-g``).
        retries: connection attempts, 1 s apart, while sumo-gui loads the network.

    sumo-gui's output and its error log (which in the GUI would only show in the window)
    go to temporary files; if it exits before TraCI connects, their error lines become
    the SumoStartError's message, one line.
    """
    import traci

    check_display()
    port = traci.getFreeSocketPort()
    with tempfile.TemporaryDirectory(prefix="cosim-sumo-gui-") as tmp:
        out_log, err_log = Path(tmp) / "output.log", Path(tmp) / "error.log"
        cmd = [*cmd, "--start", "true", "--quit-on-end", str(bool(quit_on_end)).lower(),
               "--delay", f"{float(delay_ms):g}", "--error-log", str(err_log),
               "--remote-port", str(port)]
        if view_settings:
            (Path(tmp) / "view.xml").write_text(VIEW_SETTINGS_XML)
            cmd += ["--gui-settings-file", str(Path(tmp) / "view.xml")]
        proc = None
        try:
            with out_log.open("wb") as out:
                proc = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT)
            # traci prints " Retrying in 1 seconds" while sumo-gui is still loading
            with contextlib.redirect_stdout(io.StringIO()):
                traci.init(port, numRetries=retries, proc=proc)
        except Exception as exc:
            if proc is not None and proc.poll() is None:
                proc.kill()
            if proc is not None:
                proc.wait()
            detail = _gui_errors(err_log, out_log) or " ".join(str(exc).split())
            raise SumoStartError(
                f"sumo-gui failed to start: {detail or type(exc).__name__}"
            ) from None
    # the folder is gone; sumo-gui keeps writing to its open (now nameless) files
    return traci


def screenshot(ts, path: str | Path, view: str = DEFAULT_VIEW, step: bool = True,
               timeout_s: float = 5.0) -> Path:
    """Save sumo-gui's ``view`` to ``path`` (format from the suffix, e.g. ``.png``).

    TraCI's ``gui.screenshot`` only schedules the picture; sumo-gui draws it at the end
    of the next simulation step. With ``step=True`` this makes that step (the simulation
    advances by one step length) and waits up to ``timeout_s`` seconds for the file;
    with ``step=False`` the caller's next step writes it (use this inside a cosim run,
    whose loop must make every step itself).

    Args:
        ts: the ``traci`` module (or connection) of a running sumo-gui.
        path: image file to write; made absolute (sumo-gui may run elsewhere).
    Returns:
        The absolute path.
    """
    path = Path(path).resolve()
    path.parent.mkdir(parents=True, exist_ok=True)
    ts.gui.screenshot(view, str(path))
    if step:
        ts.simulationStep()
        end = time.monotonic() + timeout_s
        while not (path.is_file() and path.stat().st_size > 0):
            if time.monotonic() > end:
                raise SumoStartError(f"sumo-gui wrote no screenshot to {path}")
            time.sleep(0.05)
    return path
