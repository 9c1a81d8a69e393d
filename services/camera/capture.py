"""The camera service's source: frames from OpenCV (a V4L2 device, a video file, a network
stream) on a thread of its own, turned into Miro::ImageEventIDL and handed to a callback.

OpenCV's reads block, so the source does not run on the reactor: it plays the part of the
Connection (opening the device, reopening it with back-off when it fails or goes away) and of the
Consumer (a frame into the IDL type) in one thread; the Implementation it feeds is thread-safe.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import Miro
from Miro.CameraParameters import CameraParameters
from miro_gen import log

_log = log.logger("Camera")

E = Miro.ImageEncodingIDL
ENCODINGS = {"mono8": E.IMAGE_MONO8, "rgb8": E.IMAGE_RGB8, "bgr8": E.IMAGE_BGR8,
             "jpeg": E.IMAGE_JPEG, "png": E.IMAGE_PNG}  # fmt: skip
RETRY_FIRST, RETRY_MAX = 0.1, 5.0  # seconds between attempts to open the source


def open_capture(device: str) -> Any:
    """A cv2.VideoCapture for `device`: a number or /dev/video* through V4L2, anything else
    (a file, a URL) through FFmpeg."""
    if device.isdigit():
        return cv2.VideoCapture(int(device), cv2.CAP_V4L2)
    if device.startswith("/dev/video"):
        return cv2.VideoCapture(device, cv2.CAP_V4L2)
    return cv2.VideoCapture(device)


class FrameSource:
    """Reads `params.device` and calls `deliver(image, stamp)` for each frame to publish."""

    def __init__(
        self, params: CameraParameters, deliver: Callable[[Miro.ImageEventIDL, float], None]
    ) -> None:
        if params.encoding not in ENCODINGS:
            raise ValueError(f"Encoding {params.encoding!r}: one of {', '.join(ENCODINGS)}")
        sizes = min(params.width, params.height)
        if not 1 <= params.quality <= 100 or params.rate < 0 or sizes < 0:
            raise ValueError("Quality is 1 to 100; Rate, Width and Height are 0 or more")
        self.params = params
        self.deliver = deliver
        self.file = False  # the source is a file (known once opened)
        self.frames = 0  # published
        self.read = 0  # read from the source
        self.skipped = 0  # read but not published, to keep to the rate
        self.failed = 0  # read but not converted
        self.opened = 0  # times the source was opened
        self.format = Miro.ImageFormatIDL(params.width, params.height, ENCODINGS[params.encoding])
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="camera-capture", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(5)

    def _run(self) -> None:
        delay = RETRY_FIRST
        warned = False
        while not self._stop.is_set():
            capture = open_capture(self.params.device)
            if not capture.isOpened():
                if not warned:
                    _log.warning("cannot open %s (retrying)", self.params.device)
                    warned = True
                self._stop.wait(delay)
                delay = min(2 * delay, RETRY_MAX)
                continue
            delay, warned = RETRY_FIRST, False
            self.file = Path(self.params.device).is_file()
            self.opened += 1
            _log.notice("%s opened", self.params.device)
            try:
                ended = self._read(capture)
            finally:
                capture.release()
            if ended and not self.params.loop:
                _log.notice("%s: the end of the video", self.params.device)
                return
            if not ended:
                _log.warning("%s lost (reopening)", self.params.device)

    def _read(self, capture: Any) -> bool:
        """Frames until the source fails (False) or a file ends (True) or stop()."""
        p = self.params
        if not self.file:
            if p.width and p.height:
                capture.set(cv2.CAP_PROP_FRAME_WIDTH, p.width)
                capture.set(cv2.CAP_PROP_FRAME_HEIGHT, p.height)
            if p.rate:
                capture.set(cv2.CAP_PROP_FPS, p.rate)
        own = capture.get(cv2.CAP_PROP_FPS)
        rate = p.rate or (own if self.file and math.isfinite(own) and own > 0 else 0.0)
        period = 1.0 / rate if rate else 0.0
        due = time.monotonic()
        while not self._stop.is_set():
            ok, frame = capture.read()
            if not ok:
                return self.file
            self.read += 1
            now = time.monotonic()
            if period and self.file:  # a file: at the rate, every frame
                if self._stop.wait(max(0.0, due - now)):
                    return False
                due += period
            elif period:  # live: skip what comes before its time
                if now < due - period / 2:
                    self.skipped += 1
                    continue
                due = max(due + period, now - period / 2)
            stamp = time.time()
            try:
                image = self._image(frame, stamp)
            except (ValueError, cv2.error) as e:  # a frame OpenCV cannot convert: not the next
                self.failed += 1
                _log.error("frame %d: %s", self.read, e)
                continue
            self.deliver(image, stamp)
            self.frames += 1
        return False

    def _image(self, frame: Any, stamp: float) -> Miro.ImageEventIDL:
        p = self.params
        height, width = frame.shape[:2]
        if p.width and p.height and (width, height) != (p.width, p.height):
            frame = cv2.resize(frame, (p.width, p.height), interpolation=cv2.INTER_AREA)
            width, height = p.width, p.height
        encoding = ENCODINGS[p.encoding]
        step = 0
        if encoding is E.IMAGE_JPEG or encoding is E.IMAGE_PNG:
            jpeg = encoding is E.IMAGE_JPEG
            options = [cv2.IMWRITE_JPEG_QUALITY, p.quality] if jpeg else []
            ok, encoded = cv2.imencode(".jpg" if jpeg else ".png", frame, options)
            if not ok:
                raise ValueError(f"OpenCV cannot encode a {width}x{height} frame as {p.encoding}")
            data = encoded.tobytes()
        else:
            if encoding is E.IMAGE_RGB8:
                frame = cv2.cvtColor(frame, cv2.COLOR_BGR2RGB)
            elif encoding is E.IMAGE_MONO8:
                frame = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
            data = frame.tobytes()
            step = len(data) // height
        self.format = Miro.ImageFormatIDL(width, height, encoding, step)
        sec = math.floor(stamp)
        time_idl = Miro.TimeIDL(sec, min(999_999, round((stamp - sec) * 1e6)))
        return Miro.ImageEventIDL(time_idl, self.frames, self.format, data)
