"""Saving wrist-camera frames of a run: PNG files in a directory, or one video file."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

VIDEO_SUFFIXES = {".mp4": "mp4v", ".avi": "MJPG"}


class FrameRecorder:
    """Writes RGB frames to `path`: a video when it ends in .mp4/.avi, else numbered PNGs in that directory."""

    def __init__(self, path: Path, fps: float, every: int = 1):
        self.path, self.fps, self.every = Path(path), fps, max(1, int(every))
        self.frames_seen = 0
        self.frames_written = 0
        self._video: cv2.VideoWriter | None = None
        if self.path.suffix.lower() in VIDEO_SUFFIXES:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        else:
            self.path.mkdir(parents=True, exist_ok=True)

    def add(self, rgb: np.ndarray) -> None:
        self.frames_seen += 1
        if (self.frames_seen - 1) % self.every:
            return
        bgr = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
        codec = VIDEO_SUFFIXES.get(self.path.suffix.lower())
        if codec is None:
            target = self.path / f"frame_{self.frames_written:06d}.png"
            if not cv2.imwrite(str(target), bgr):
                raise OSError(f"could not write {target}")
        else:
            if self._video is None:
                self._video = cv2.VideoWriter(str(self.path), cv2.VideoWriter_fourcc(*codec), self.fps / self.every,
                                              (rgb.shape[1], rgb.shape[0]))
                if not self._video.isOpened():
                    raise OSError(f"could not open a {codec} video writer for {self.path}")
            self._video.write(bgr)
        self.frames_written += 1

    def close(self) -> None:
        if self._video is not None:
            self._video.release()
            self._video = None
