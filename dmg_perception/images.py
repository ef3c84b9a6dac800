"""sensor_msgs/Image fields -> a grey numpy image, without cv_bridge (not installable here)."""
from __future__ import annotations

import cv2
import numpy as np

# encoding -> (channels, dtype, conversion to grey or None)
ENCODINGS = {
    "mono8": (1, np.uint8, None),
    "8UC1": (1, np.uint8, None),
    "rgb8": (3, np.uint8, cv2.COLOR_RGB2GRAY),
    "bgr8": (3, np.uint8, cv2.COLOR_BGR2GRAY),
    "rgba8": (4, np.uint8, cv2.COLOR_RGBA2GRAY),
    "bgra8": (4, np.uint8, cv2.COLOR_BGRA2GRAY),
    "mono16": (1, np.uint16, None),
}


class ImageError(ValueError):
    """An image message that cannot be read; the message says why."""


def grey_image(encoding: str, width: int, height: int, step: int, data, big_endian: bool = False) -> np.ndarray:
    """The image as an 8-bit grey array (height, width); rows may be padded (step >= width * pixel size)."""
    if encoding not in ENCODINGS:
        raise ImageError(f"unsupported encoding '{encoding}' (supported: {', '.join(ENCODINGS)})")
    channels, dtype, conversion = ENCODINGS[encoding]
    pixel = channels * np.dtype(dtype).itemsize
    if width <= 0 or height <= 0:
        raise ImageError(f"empty image {width}x{height}")
    if step < width * pixel:
        raise ImageError(f"step {step} is smaller than a row of {width} {encoding} pixels ({width * pixel} bytes)")
    buffer = np.frombuffer(data, np.uint8)
    if buffer.size != step * height:
        raise ImageError(f"{buffer.size} bytes of data for {height} rows of {step} bytes ({step * height} expected)")
    rows = buffer.reshape(height, step)[:, : width * pixel]
    image = rows.view(np.dtype(dtype).newbyteorder(">" if big_endian else "<")).reshape(height, width, channels)
    if dtype == np.uint16:
        image = (image >> 8).astype(np.uint8)
    if conversion is None:
        return np.ascontiguousarray(image[:, :, 0])
    return cv2.cvtColor(np.ascontiguousarray(image), conversion)
