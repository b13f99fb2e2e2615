"""PNG camera observations (docs/protocol.md, "Observation payloads"): one or more PNG files
concatenated, mapped to C×H×W.

Unity packs up to 3 channels per PNG and concatenates the files; ``compressed_channel_mapping``
then says which output channel each decoded channel feeds (``-1`` drops it, shared targets are
averaged). Without a mapping the legacy rule applies: one expected channel means grayscale (the
mean of the first image's channels), otherwise the first ``shape[0]`` decoded channels are kept.
"""
from __future__ import annotations

import io
import struct
import zlib
from typing import Sequence

import numpy as np
from PIL import Image

from protos.errors import ProtocolError

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_CHUNK_HEADER = struct.Struct(">I4s")  # length, chunk type


def split_concatenated_pngs(data: bytes) -> list[bytes]:
    """Cut ``data`` into its complete PNG files.

    Each file is walked chunk by chunk up to its IEND chunk (so signature-like bytes inside image
    data cannot cut it short); the next file starts at the next PNG signature after that point.
    Bytes after the last file that hold no signature are ignored.
    """
    if not data.startswith(PNG_SIGNATURE):
        raise ProtocolError(
            "A PNG observation does not start with the PNG signature; the simulator sent "
            "garbled compressed_data. Rebuild the environment with a supported ML-Agents package."
        )
    files: list[bytes] = []
    start = 0
    while start >= 0:
        end = _end_of_png(data, start)
        files.append(data[start:end])
        start = data.find(PNG_SIGNATURE, end)
    return files


def _end_of_png(data: bytes, start: int) -> int:
    """Offset just past the IEND chunk of the PNG file that begins at ``start``."""
    pos = start + len(PNG_SIGNATURE)
    while pos + _CHUNK_HEADER.size <= len(data):
        length, chunk_type = _CHUNK_HEADER.unpack_from(data, pos)
        pos += _CHUNK_HEADER.size + length + 4  # data + CRC
        if chunk_type == b"IEND":
            return min(pos, len(data))
    raise ProtocolError(
        "A PNG observation is truncated (no IEND chunk); the simulator sent garbled compressed_data."
    )


def _png_to_chw(png: bytes, height: int, width: int) -> np.ndarray:
    """Decode one PNG file to float32 [channels, H, W] in [0, 1].

    Its IHDR chunk must declare ``height`` x ``width`` (the sensor's shape) before anything is
    decompressed: a PNG of a few hundred bytes can declare 20000 x 20000 pixels (1.2 GB once
    decoded). Anything Pillow cannot decode is a ProtocolError."""
    size = _ihdr_size(png)
    if size != (width, height):
        raise ProtocolError(
            f"A PNG observation declares {size[0]}x{size[1]} pixels but the sensor's shape needs "
            f"{width}x{height}; check the camera/render-texture sensor settings in the Unity scene."
        )
    try:
        with Image.open(io.BytesIO(png), formats=("PNG",)) as image:
            if image.mode not in ("L", "RGB", "RGBA"):
                image = image.convert("RGB")
            pixels = np.asarray(image, dtype=np.float32) / 255.0
    except (OSError, SyntaxError, ValueError, EOFError, zlib.error, Image.DecompressionBombError) as error:
        raise ProtocolError(
            f"A PNG observation could not be decoded ({type(error).__name__}: {error}); the simulator "
            "sent garbled compressed_data."
        ) from None
    if pixels.ndim == 2:
        return pixels[np.newaxis]
    return np.moveaxis(pixels, -1, 0)


def _ihdr_size(png: bytes) -> tuple[int, int]:
    """(width, height) from the IHDR chunk, which must come first (PNG specification 5.6)."""
    offset = len(PNG_SIGNATURE)
    if len(png) < offset + 8 + 13 or png[offset + 4:offset + 8] != b"IHDR":
        raise ProtocolError(
            "A PNG observation does not begin with an IHDR chunk; the simulator sent garbled "
            "compressed_data."
        )
    return struct.unpack_from(">II", png, offset + 8)


def _apply_channel_mapping(channels: np.ndarray, mapping: Sequence[int]) -> np.ndarray:
    """[k, H, W] decoded channels → [max(mapping)+1, H, W]; shared targets averaged, -1 dropped."""
    mapping_arr = np.asarray(mapping, dtype=np.int64)
    if len(mapping_arr) != len(channels):
        raise ProtocolError(
            f"A PNG observation decoded to {len(channels)} channels but its compressed_channel_mapping "
            f"{list(mapping)} has {len(mapping_arr)} entries; the simulator's sensor is inconsistent."
        )
    targets = sorted({int(m) for m in mapping_arr if m >= 0})
    if not targets or targets != list(range(targets[-1] + 1)):
        raise ProtocolError(
            f"The compressed_channel_mapping {list(mapping)} does not cover output channels 0..max "
            "exactly; the simulator's sensor is inconsistent."
        )
    return np.stack([channels[mapping_arr == t].mean(axis=0) for t in targets])


def decode_png_observation(
    data: bytes, shape: Sequence[int], mapping: Sequence[int] = ()
) -> np.ndarray:
    """Decode concatenated PNGs to float32 [C, H, W] equal to ``shape``, else ProtocolError."""
    images = [_png_to_chw(png, shape[1], shape[2]) for png in split_concatenated_pngs(data)]
    if sum(len(image) for image in images) > 3 * max(shape[0], len(mapping)):
        raise ProtocolError(  # more channels than the sensor can use: not what Unity sends
            f"A PNG observation holds {len(images)} images for a sensor of shape {tuple(shape)}; the "
            "simulator sent garbled compressed_data."
        )
    if len(mapping) > 0:
        result = _apply_channel_mapping(np.concatenate(images, axis=0), mapping)
    elif shape[0] == 1:
        result = images[0].mean(axis=0, keepdims=True)
    else:
        result = np.concatenate(images, axis=0)[: shape[0]]
    if tuple(result.shape) != tuple(shape):
        raise ProtocolError(
            f"A PNG observation decoded to shape {tuple(result.shape)} but the sensor declares "
            f"{tuple(shape)}; check the camera/render-texture sensor settings in the Unity scene."
        )
    return result.astype(np.float32, copy=False)
