"""The camera service (services/camera) as a process: a video file and an MJPEG stream over HTTP
(from miro_gen.sim.camera) become ImageEventIDL events and polled images, every frame, in order,
at the size and in the encoding asked for. The frames carry their numbers in a bar code."""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import Miro
import pytest
from device_rig import SERVICES, Driver
from loopback import NamingProcess, Recorder, RunningServer, eventually, service_env

from miro_gen import Client

cv2 = pytest.importorskip("cv2", reason="the camera extra: pip install 'miro-gen[camera]'")
np = pytest.importorskip("numpy")
camera = pytest.importorskip("miro_gen.sim.camera")

E = Miro.ImageEncodingIDL


class CameraRig:
    """A naming service, the camera service on `device`, a consumer of its images, a stub."""

    def __init__(self, tmp: Path, device: str | Path, **parameters: object) -> None:
        self.naming = NamingProcess()
        self.driver = Driver(
            "camera", "Camera", self.naming.endpoint, tmp / "camera.log",
            Device=device, **parameters,
        )  # fmt: skip
        self.gui = RunningServer(self.naming.endpoint, "gui")
        self.events = Recorder(self.gui.server.resolve_channel("rover/EventChannel"))
        self.events.set_subscriptions([("rover", "Image")])
        self.client = Client(["t", "--naming", self.naming.endpoint])
        self.camera = self.client.resolve_name("rover/Camera", Miro.Camera)
        eventually(lambda: self.driver.logged("someone subscribes") == 1)

    def images(self) -> list[Miro.ImageEventIDL]:
        return [e.payload for e in self.events.events]  # type: ignore[misc]

    def close(self) -> str:
        try:
            return self.driver.stop() if self.driver.proc.poll() is None else ""
        finally:
            self.driver.kill()
            self.client.close()
            self.gui.stop()
            self.naming.stop()


@pytest.fixture
def rigs() -> Iterator[list[CameraRig]]:
    made: list[CameraRig] = []
    yield made
    for rig in made:
        rig.close()


def pixels(image: Miro.ImageEventIDL) -> object:
    f = image.format
    if f.encoding in (E.IMAGE_JPEG, E.IMAGE_PNG):
        return cv2.imdecode(np.frombuffer(image.data, np.uint8), cv2.IMREAD_COLOR)
    channels = 1 if f.encoding == E.IMAGE_MONO8 else 3
    flat = np.frombuffer(image.data, np.uint8).reshape(f.height, f.step)
    return flat[:, : f.width * channels].reshape(f.height, f.width, channels).squeeze()


def test_a_video_file_every_frame_in_order_scaled(tmp_path: Path, rigs: list[CameraRig]) -> None:
    video = tmp_path / "drive.avi"
    # The service starts before the file exists: it keeps trying, and takes it when it comes
    # (after the consumer has subscribed, so that no frame goes unseen).
    rig = CameraRig(tmp_path, video, Width=320, Height=180, Rate=30, Encoding="rgb8")
    rigs.append(rig)
    made = tmp_path / "making.avi"
    camera.write_video(made, 45, 640, 360, 25.0)
    made.rename(video)
    eventually(lambda: rig.driver.logged("the end of the video") == 1, 30)
    eventually(lambda: len(rig.events.events) == 45)
    images = rig.images()
    assert [i.frame for i in images] == list(range(45)) and rig.events.missed == 0
    first = images[0].format
    assert (first.width, first.height, first.encoding, first.step) == (320, 180, E.IMAGE_RGB8, 960)
    numbers = [camera.frame_number(cv2.cvtColor(pixels(i), cv2.COLOR_RGB2BGR)) for i in images]
    assert numbers == list(range(45))
    stamps = [i.time.sec + i.time.usec / 1e6 for i in images]
    assert stamps[-1] - stamps[0] >= 44 / 30 * 0.95  # at the rate asked for, not faster
    assert rig.camera.getFormat() == first
    assert rig.camera.getImage().frame == 44
    with pytest.raises(Miro.ETimeOut):
        rig.camera.getWaitImage()
    summary = rig.close()
    assert "45 frames read, 0 skipped for the rate, 45 images, 45 published" in summary, summary


def test_an_mjpeg_stream_as_jpeg_and_grey(tmp_path: Path, rigs: list[CameraRig]) -> None:
    stream = camera.MjpegStream(640, 480, 30)
    stream.serve()
    try:
        rig = CameraRig(tmp_path, stream.url, Encoding="jpeg", Quality=80, Rate=10)
        rigs.append(rig)
        image = rig.camera.getWaitImage()
        assert image.format.encoding == E.IMAGE_JPEG and image.data[:2] == b"\xff\xd8"
        eventually(lambda: len(rig.events.events) >= 8, 20)
        numbers = [camera.frame_number(pixels(i)) for i in rig.images()]
        assert None not in numbers and numbers == sorted(set(numbers))
        summary = rig.close()
        assert " 0 skipped for the rate" not in summary, summary  # 10 of the 30 a second
        assert "0 dropped" in summary, summary
    finally:
        stream.close()


def test_without_opencv_the_service_says_what_to_install(tmp_path: Path) -> None:
    (tmp_path / "cv2.py").write_text("raise ImportError('No module named cv2')\n")
    env = service_env()
    env["PYTHONPATH"] = os.pathsep.join([str(tmp_path), env["PYTHONPATH"]])
    naming = NamingProcess()
    try:
        done = subprocess.run(
            [sys.executable, str(SERVICES / "camera"), "--naming", naming.endpoint],
            capture_output=True,
            text=True,
            env=env,
            timeout=30,
        )
    finally:
        naming.stop()
    assert done.returncode == 1, done.stderr
    assert "pip install 'miro-gen[camera]'" in done.stderr and "Traceback" not in done.stderr
