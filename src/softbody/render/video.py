"""MP4 (H.264 through imageio-ffmpeg's bundled ffmpeg) and GIF encoding.

softbody starts ffmpeg itself (not through imageio's writer) so that it owns the child
process: ffmpeg's messages go to a temporary file, not the terminal, and a failed
encode is reported as one line (:class:`VideoError`) with ffmpeg's last message; a run
that stops early (an error, Ctrl-C, SIGTERM) kills and reaps ffmpeg (:meth:`abort`)
instead of leaving it behind or letting it complain about a removed folder.
"""

from __future__ import annotations

import subprocess
import tempfile
from fractions import Fraction
from pathlib import Path

import numpy as np

#: libx264 constant rate factor: imageio's ``quality=7`` (int((1 - 7 / 10) * 51)).
CRF = 15
#: Frame sides are padded up to a multiple of this (H.264 macroblocks, as before).
MACRO_BLOCK = 8
#: Seconds ffmpeg may take to finish the file once the last frame is sent.
FINISH_TIMEOUT = 600.0


class VideoError(RuntimeError):
    """ffmpeg could not write the video; the message is one line."""


class VideoWriter:
    """Streams frames into an MP4 file; also keeps a half-size, half-rate copy for a GIF."""

    def __init__(self, path: Path, fps: float, *, gif: bool = True):
        self.path = Path(path)
        self.fps = fps
        self._process: subprocess.Popen | None = None
        self._log = None
        self._size: tuple[int, int] | None = None
        self._gif_frames: list[np.ndarray] | None = [] if gif else None
        self.frame_count = 0

    def _start(self, height: int, width: int) -> None:
        import imageio_ffmpeg

        cmd = [
            imageio_ffmpeg.get_ffmpeg_exe(),
            "-y",
            "-f", "rawvideo",
            "-vcodec", "rawvideo",
            "-s", f"{width}x{height}",
            "-pix_fmt", "rgb24",
            "-r", str(Fraction(self.fps).limit_denominator()),
            "-i", "-",
            "-an",
            "-vcodec", "libx264",
            "-pix_fmt", "yuv420p",
            "-crf", str(CRF),
        ]  # fmt: skip
        padded = [-(-side // MACRO_BLOCK) * MACRO_BLOCK for side in (width, height)]
        if padded != [width, height]:
            cmd += ["-vf", f"scale={padded[0]}:{padded[1]}"]
        cmd += ["-v", "error", str(self.path)]
        self._log = tempfile.TemporaryFile()
        # a session of its own: the terminal's Ctrl-C reaches softbody, which then kills
        # ffmpeg itself (abort) rather than ffmpeg printing its own complaint
        self._process = subprocess.Popen(
            cmd,
            stdin=subprocess.PIPE,
            stdout=subprocess.DEVNULL,
            stderr=self._log,
            start_new_session=True,
        )
        self._size = (height, width)

    def _failure(self, what: str) -> VideoError:
        """A one-line error with ffmpeg's last message (after ffmpeg has ended)."""
        last = ""
        if self._log is not None:
            self._log.seek(0)
            lines = self._log.read()[-4096:].decode(errors="replace").strip().splitlines()
            last = lines[-1].strip() if lines else ""
        code = self._process.returncode if self._process is not None else None
        detail = f": {last}" if last else f" (ffmpeg exit status {code})"
        return VideoError(f"{self.path.name}: {what}{detail}")

    def append(self, frame: np.ndarray) -> None:
        """Add an (H, W, 3) uint8 frame."""
        frame = np.ascontiguousarray(frame, dtype=np.uint8)
        if self._process is None:
            self._start(*frame.shape[:2])
        elif frame.shape[:2] != self._size:
            raise ValueError(f"frame is {frame.shape[:2]}, the video {self._size}")
        try:
            self._process.stdin.write(frame.tobytes())
        except OSError:  # ffmpeg ended (a full disk, a removed folder): say why
            self._stop()
            error = self._failure("ffmpeg stopped while encoding")
            self._close_log()
            raise error from None
        if self._gif_frames is not None and self.frame_count % 2 == 0:
            self._gif_frames.append(frame[::2, ::2].copy())
        self.frame_count += 1

    def close(self) -> None:
        """Finish the MP4; :class:`VideoError` when ffmpeg fails."""
        p = self._process
        if p is None:
            return
        try:
            p.stdin.close()
        except OSError:
            pass
        try:
            code = p.wait(timeout=FINISH_TIMEOUT)
        except subprocess.TimeoutExpired:
            self.abort()
            raise self._failure(f"ffmpeg did not finish in {FINISH_TIMEOUT:.0f} s") from None
        if code != 0:
            error = self._failure("ffmpeg failed")
            self.abort()
            raise error
        self._process = None
        self._close_log()

    def abort(self) -> None:
        """Kill ffmpeg (if running) and wait for it; safe to call more than once."""
        self._stop()
        self._close_log()

    def _stop(self) -> None:
        p = self._process
        if p is not None:
            if p.poll() is None:
                p.kill()
            try:
                p.stdin.close()
            except OSError:
                pass
            p.wait()

    def _close_log(self) -> None:
        if self._log is not None:
            self._log.close()
            self._log = None

    def write_gif(self, path: Path) -> None:
        """Write the kept frames as a looping GIF at half the frame rate."""
        import imageio.v2 as imageio

        if not self._gif_frames:
            return
        imageio.mimsave(str(path), self._gif_frames, format="GIF", duration=2.0 / self.fps, loop=0)
