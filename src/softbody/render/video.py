"""MP4 (H.264 through imageio-ffmpeg's bundled ffmpeg) and GIF encoding."""

from __future__ import annotations

from pathlib import Path

import numpy as np


class VideoWriter:
    """Streams frames into an MP4 file; also keeps a half-size, half-rate copy for a GIF."""

    def __init__(self, path: Path, fps: float, *, gif: bool = True):
        import imageio.v2 as imageio

        self.path = path
        self.fps = fps
        self._writer = imageio.get_writer(
            str(path),
            fps=fps,
            codec="libx264",
            quality=7,
            pixelformat="yuv420p",
            macro_block_size=8,
            ffmpeg_log_level="error",
        )
        self._gif_frames: list[np.ndarray] | None = [] if gif else None
        self.frame_count = 0

    def append(self, frame: np.ndarray) -> None:
        """Add an (H, W, 3) uint8 frame."""
        self._writer.append_data(frame)
        if self._gif_frames is not None and self.frame_count % 2 == 0:
            self._gif_frames.append(frame[::2, ::2].copy())
        self.frame_count += 1

    def close(self) -> None:
        self._writer.close()

    def write_gif(self, path: Path) -> None:
        """Write the kept frames as a looping GIF at half the frame rate."""
        import imageio.v2 as imageio

        if not self._gif_frames:
            return
        imageio.mimsave(str(path), self._gif_frames, format="GIF", duration=2.0 / self.fps, loop=0)
