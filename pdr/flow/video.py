"""Read a leg-camera video into grey frames, with clear errors for unreadable or truncated files."""

from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np

from pdr.errors import InputError

# FFmpeg's own decoder messages ("Slice pointer chain broken") would add lines to stderr; every problem they
# signal is reported here as one InputError instead. Read when OpenCV's FFmpeg backend opens its first file.
os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")


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
    if not path.is_file():
        raise InputError(f"{path}: expected a video file, found nothing there")
    cap = cv2.VideoCapture(str(path))
    try:
        if not cap.isOpened():
            raise InputError(f"{path}: expected a video OpenCV can decode (e.g. FFV1 or MJPG in AVI), found an unreadable file")
        announced = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
        frames = []
        while max_frames is None or len(frames) < max_frames:
            ok, frame = cap.read()
            if not ok:
                break
            if frame.ndim == 3:
                frame = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
            frames.append(frame)
    finally:
        cap.release()
    if not frames:
        raise InputError(f"{path}: expected video frames, found none decodable (empty, truncated or corrupt file)")
    n = len(frames)
    if max_frames is None and announced > 0 and n < announced:
        raise InputError(f"{path}: expected {announced} frames as its header says, decoded only {n} (truncated or corrupt video)")
    if expected_frames is not None and max_frames is None and n != expected_frames:
        raise InputError(f"{path}: expected {expected_frames} frames (one per row of frames.csv), found {n} in the video")
    return np.stack(frames)
