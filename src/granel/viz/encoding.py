"""Movies written to disk: frames streamed to an MP4 through imageio-ffmpeg (libx264), a GIF in its
place when the encoder fails, each file atomic and marked as granel's (`write_movie`)."""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

import numpy as np

# x264 speed preset, faster than the default 'medium' at the same constant quality (quality=7,
# CRF 15) for a slightly larger file (docs/performance.md)
X264_PRESET = "veryfast"


def _movie_mark() -> str:
    from .. import __version__
    from ..guard.owners import MARK

    return f"{MARK} {__version__}"


MOVIE_MARK = _movie_mark()


class _EncoderFailed(Exception):
    """The MP4 encoder (not the rendering) failed."""


def _stream_mp4(out: Path, frames: Iterator[np.ndarray], fps: int) -> None:
    import imageio.v2 as imageio

    try:
        w = imageio.get_writer(out, fps=fps, codec="libx264", quality=7, macro_block_size=16, ffmpeg_log_level="quiet",
                               output_params=["-preset", X264_PRESET, "-metadata", f"comment={MOVIE_MARK}"])
    except Exception as e:  # noqa: BLE001 - no ffmpeg, no libx264, ...
        raise _EncoderFailed(str(e)) from e
    try:
        for f in frames:  # an error while rendering propagates as itself
            try:
                w.append_data(f)
            except Exception as e:  # noqa: BLE001
                raise _EncoderFailed(str(e)) from e
    except BaseException:
        try:
            w.close()
        except Exception:  # noqa: BLE001 - the first error is the one to report
            pass
        raise
    try:
        w.close()
    except Exception as e:  # noqa: BLE001
        raise _EncoderFailed(str(e)) from e


def _mp4_complete(path: Path) -> bool:
    """Whether an MP4 file holds its index (the moov box, which ffmpeg writes last)."""
    try:
        size = path.stat().st_size
        with open(path, "rb") as fh:
            head = fh.read(1 << 16)
            fh.seek(max(0, size - (1 << 20)))
            tail = fh.read()
    except OSError:
        return False
    return b"moov" in head or b"moov" in tail


def write_movie(frames: Callable[[], Iterator[np.ndarray]] | Sequence[np.ndarray], out, fps: int) -> Path:
    """Stream frames to an MP4 through imageio-ffmpeg (libx264); a GIF next to it if the encoder
    fails (or if `out` ends in .gif). `frames` is an iterable of RGB arrays or, so that a failed
    MP4 can be re-rendered as GIF without keeping the frames, a callable returning a fresh iterator.
    Each file is written atomically with granel's mark (`guard.writing.atomic_path`); a full disk
    is an error (exit 4), not a reason to try a GIF; a GIF is never written over a file granel did
    not write."""
    import imageio.v2 as imageio

    from ..guard.exits import FileError, is_no_space
    from ..guard.owners import is_granel_file
    from ..guard.writing import atomic_path

    make = frames if callable(frames) else (lambda: iter(frames))
    out = Path(out)
    if out.suffix.lower() != ".gif":
        try:
            with atomic_path(out, keep_suffix=True) as tmp:
                _stream_mp4(Path(tmp), make(), fps)
                if not _mp4_complete(Path(tmp)):  # ffmpeg reports a failed trailer (a full disk) only on its stderr
                    import shutil

                    free = shutil.disk_usage(Path(tmp).parent).free
                    why = "no space left on the device" if free < 1 << 20 else "the encoder ended without its index"
                    raise _EncoderFailed(why)
            return out
        except _EncoderFailed as e:
            if is_no_space(e) or is_no_space(e.__cause__ or e):
                raise FileError(f"{out}: no space left on the device; nothing was written there") from None
            gif = out.with_suffix(".gif")
            if gif.exists() and not is_granel_file(gif):
                raise FileError(f"{out}: the MP4 encoder failed ({e}), and the GIF in its place, {gif}, exists and was "
                                "not written by granel") from None
            out = gif
    import io

    from ..guard.writing import write_bytes

    buffer = io.BytesIO()  # encoded in memory: the disk sees one plain, atomic write
    with imageio.get_writer(buffer, format="GIF", mode="I", duration=1000.0 / fps, loop=0,
                            comment=MOVIE_MARK.encode()) as w:
        for f in make():
            w.append_data(f)
    write_bytes(out, buffer.getvalue())
    return out
