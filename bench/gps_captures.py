"""Real receivers' logs through the GPS driver, fix by fix against gpsd: the agreement figure.

    python bench/gps_captures.py [NAME.log ...]

Every NMEA log of gpsd's regression suite that has been fetched beside the checkout (see
tests/nmea_captures.py) is written, as fast as the driver reads it, into a pseudo-terminal that
services/gps reads in a process of its own; the valid readings it publishes are compared with the
fixes gpsd reported for the same log (its .chk file): missing, extra, and at another position.
Not a speed benchmark: a measurement of correctness that takes minutes, so it is not a test
(tests/devices/test_gps_captures.py runs every log through the parser, and a few through the
driver).
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT), str(ROOT / "tests")]

from device_rig import GpsRig  # noqa: E402
from nmea_captures import compare, data_lines, gpsd_fixes, gpsd_logs, valid_fixes  # noqa: E402


def main() -> int:
    wanted = set(sys.argv[1:])
    logs = [log for log in gpsd_logs() if not wanted or log.name in wanted]
    if not logs:
        print("no logs: fetch gpsd's test/daemon into ../shared/captures/gpsd", file=sys.stderr)
        return 1
    agree = 0
    start = time.monotonic()
    for log in logs:
        with tempfile.TemporaryDirectory() as tmp:
            rig = GpsRig(Path(tmp))
            try:
                readings = rig.replay(data_lines(log))
            finally:
                rig.close()
        result = compare(gpsd_fixes(log), valid_fixes(readings))
        agree += result.agree
        mark = "agrees" if result.agree else str(result)
        print(f"{log.name:40s} {len(readings):5d} readings  {mark}", flush=True)
    print(
        f"{agree} of {len(logs)} logs give exactly gpsd's fixes through the driver "
        f"({time.monotonic() - start:.0f} s)"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
