"""Read a leg-camera video into grey frames, with clear errors for unreadable or truncated files."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Iterator

import cv2
import numpy as np

from pdr.errors import InputError

# FFmpeg's own decoder messages ("Slice pointer chain broken") would add lines to stderr; every problem they
# signal is reported here as one InputError instead. Read when OpenCV's FFmpeg backend opens its first file.
os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")


def _grey_frames(path: Path, max_frames: int | None) -> Iterator[tuple[int, np.ndarray]]:
    """``(announced frame count, grey frame)`` for each decodable frame of ``path``; InputError if it cannot be opened."""
    if not path.is_file():
        raise InputError(f"{path}: expected a video file, found nothing there")
    cap = cv2.VideoCapture(str(path))
    try:
        if not cap.isOpened():
            raise InputError(f"{path}: expected a video OpenCV can decode (e.g. FFV1 or MJPG in AVI), found an unreadable file")
        announced = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
        n = 0
        while max_frames is None or n < max_frames:
            ok, frame = cap.read()
            if not ok:
                break
            n += 1
            yield announced, (cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY) if frame.ndim == 3 else frame)
    finally:
        cap.release()


def _check_count(path: Path, n: int, announced: int, expected_frames: int | None, complete: bool) -> None:
    if n == 0:
        raise InputError(f"{path}: expected video frames, found none decodable (empty, truncated or corrupt file)")
    if complete and announced > 0 and n < announced:
        raise InputError(f"{path}: expected {announced} frames as its header says, decoded only {n} (truncated or corrupt video)")
    if expected_frames is not None and complete and n != expected_frames:
        raise InputError(f"{path}: expected {expected_frames} frames (one per row of frames.csv), found {n} in the video")


def read_video(path: str | Path, *, expected_frames: int | None = None, max_frames: int | None = None) -> np.ndarray:
    """All frames of ``path`` as an (N, H, W) uint8 grey array.

    Parameters
    ----------
    path : the video file (``video.avi`` / ``video.mp4``).
    expected_frames : the number of frames the caller knows of (rows of ``frames.csv``); a different count
        decoded is an InputError.
    max_frames : stop after this many frames (None: all).

    Raises
    ------
    InputError : the file is missing, cannot be opened or decoded, holds no frame, or holds fewer frames than its
        header announces (a truncated file) or than ``expected_frames``.
    """
    path = Path(path)
    announced, frames = 0, []
    for announced, frame in _grey_frames(path, max_frames):
        frames.append(frame)
    _check_count(path, len(frames), announced, expected_frames, max_frames is None)
    return np.stack(frames)


def check_video(path: str | Path, *, width_px: int, height_px: int, expected_frames: int | None = None) -> int:
    """Decode every frame of ``path`` without keeping them (what :func:`read_video` would refuse, refused here
    too, for ``pdr validate``) and check their size against the camera's ``width_px x height_px``. Returns the
    number of frames."""
    path = Path(path)
    announced, n = 0, 0
    for announced, frame in _grey_frames(path, None):
        if frame.shape != (height_px, width_px):
            raise InputError(f"{path}: expected {width_px}x{height_px} frames as camera.toml says, "
                             f"found {frame.shape[1]}x{frame.shape[0]} in frame {n + 1}")
        n += 1
    _check_count(path, n, announced, expected_frames, True)
    return n
