"""Red-disc target detection (chapter 7.3.3, Section C, steps 2-3).

As in the text: thresholds on the RGB channels plus a threshold on HSV saturation give a binary image;
blob analysis (OpenCV connected components) keeps the largest blob, which must pass an area and a
roundness check. The blob's outline is returned so the caller can map it to the plane and take the
centroid there (the image centroid of a tilted disc is not the image of its centre).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from skidsteer_power.mocap.config import TargetConfig


@dataclass(frozen=True)
class TargetMiss:
    """No acceptable target in a frame; ``reason`` says why (for the skipped-frame log)."""

    reason: str


@dataclass(frozen=True)
class TargetDetection:
    """A detected blob: outline (N, 2) [px, distorted image], area [px], roundness [-], and
    image centroid (x, y) [px] from the blob's moments."""

    outline_px: np.ndarray
    area_px: int
    roundness: float
    centroid_px: tuple[float, float]


def _candidate_mask(image_bgr: np.ndarray, config: TargetConfig) -> tuple[np.ndarray, int, int]:
    """Target mask (uint8 0/255) over the bounding box of the RGB-threshold pixels, and the box's
    top-left corner (x, y) [px]. The HSV conversion and blob analysis then run on that box only,
    which on a full-HD frame is several times faster than on the whole image."""
    rgb_mask = cv2.inRange(
        image_bgr,
        np.array([0, 0, config.red_min], dtype=np.uint8),
        np.array([config.blue_max, config.green_max, 255], dtype=np.uint8),
    )
    x, y, width, height = cv2.boundingRect(rgb_mask)
    if width == 0 or height == 0:
        return np.zeros((0, 0), np.uint8), 0, 0
    roi = image_bgr[y : y + height, x : x + width]
    saturation = cv2.cvtColor(roi, cv2.COLOR_BGR2HSV)[:, :, 1]
    saturated = cv2.threshold(saturation, config.saturation_min - 1, 255, cv2.THRESH_BINARY)[1]
    return cv2.bitwise_and(rgb_mask[y : y + height, x : x + width], saturated), x, y


def target_mask(image_bgr: np.ndarray, config: TargetConfig) -> np.ndarray:
    """Binary image (uint8 0/255) of the pixels passing the RGB and HSV-saturation thresholds."""
    mask = np.zeros(image_bgr.shape[:2], np.uint8)
    roi, x, y = _candidate_mask(image_bgr, config)
    mask[y : y + roi.shape[0], x : x + roi.shape[1]] = roi
    return mask


def detect_target(image_bgr: np.ndarray, config: TargetConfig) -> TargetDetection | TargetMiss:
    """Find the red disc in a BGR image; the detection, or a :class:`TargetMiss` saying why not.

    The largest connected component (8-connected) must be at least ``min_area_px``, round enough,
    and not touch the image border (a cut disc would bias the centroid).
    """
    mask, x0, y0 = _candidate_mask(image_bgr, config)
    if mask.size == 0:
        return TargetMiss('no target pixels')
    count, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    if count <= 1:
        return TargetMiss('no target pixels')
    largest = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    left, top, width, height, area = (int(v) for v in stats[largest])
    if area < config.min_area_px:
        return TargetMiss(f'largest blob {area} px < {config.min_area_px} px')
    rows, cols = image_bgr.shape[:2]
    x, y = left + x0, top + y0
    if x == 0 or y == 0 or x + width >= cols or y + height >= rows:
        return TargetMiss('target touches the image border')
    blob = (labels[top : top + height, left : left + width] == largest).astype(np.uint8)
    contours, _ = cv2.findContours(blob, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    outline = max(contours, key=len).reshape(-1, 2).astype(np.float64) + np.array([x, y])
    perimeter = cv2.arcLength(outline.astype(np.float32).reshape(-1, 1, 2), closed=True)
    roundness = 4 * math.pi * area / perimeter**2 if perimeter > 0 else 0.0
    if roundness < config.min_roundness:
        return TargetMiss(f'largest blob not round (roundness {roundness:.2f} < {config.min_roundness})')
    moments = cv2.moments(blob, binaryImage=True)
    centroid = (x + moments['m10'] / moments['m00'], y + moments['m01'] / moments['m00'])
    return TargetDetection(outline_px=outline, area_px=area, roundness=roundness, centroid_px=centroid)
