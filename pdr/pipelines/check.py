"""The one check of a recording against CONTRACT.md: what ``pdr validate`` reports and what ``pdr run`` (and
``pdr batch``) start with, so that a recording ``validate`` calls ok is one ``run`` reads.

:func:`pdr.io.recording.load_recording` checks the tables (columns, numbers, units, time, ``[subject]``, ``[geo]``,
``reference/``); on top of it come the checks of the sensors read by algorithm layers: ``camera.toml``
(:class:`pdr.flow.CameraModel`) and every frame of the leg-camera video (:func:`pdr.flow.check_video`).
"""

from __future__ import annotations

from pathlib import Path

from pdr.flow import CameraModel, check_video
from pdr.io.recording import Recording, load_recording


def check_recording(path: str | Path, *, with_reference: bool = True) -> Recording:
    """Load and check the recording at ``path`` (InputError on the first problem); ``with_reference=False`` for the
    commands that never read ``reference/``."""
    rec = load_recording(path, with_reference=with_reference)
    if rec.video_path is not None:
        cam = CameraModel.from_toml(rec.camera, what=f"{rec.path}/camera.toml")
        check_video(rec.video_path, width_px=cam.width_px, height_px=cam.height_px,
                    expected_frames=len(rec.frames) if rec.frames is not None else None)
    return rec
