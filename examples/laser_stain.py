#!/usr/bin/env python3
"""Laser stains: how far corrected photos are off colour where the other photos of their window had laser dots.

A window's median can take a laser dot into F where the dot sits in many photos of the window; every photo whose
own dot is elsewhere then shows a stain there (teal beside a red laser). This measures it on corrected photos of a
real sequence with red laser dots (the Nephrops UWTV runs of ../shared/data/real, which are not part of the
repository), as docs/evaluation.md reports ("The paths of laser dots"):

- dots: in each RAW photo, pixels whose red exceeds the larger of green and blue by 40 codes, grown by 6 pixels
  (the top 24 rows, a burned-in text line, are left out);
- for photo i, the region: the dots of the other photos within HALF_WINDOW of it, minus photo i's own dots grown
  by 25 pixels (their glow) and the top 30 rows;
- the background: the corrected photo blurred (Gaussian, sigma 25 px) with every dot of the window grown by 10
  pixels given no weight;
- the stain of photo i: the mean absolute difference, in 8-bit codes averaged over the channels, between the
  corrected photo blurred by sigma 3 px and that background over the region; reported: the mean and 90th
  percentile over the photos with a region of 50 pixels or more.

--control shifts each region down by 170 rows (off every dot): the same measure on seafloor without stains, the
texture's share of the figure. Report the stain above it.

usage: python3 laser_stain.py RAW_DIR CORRECTED_DIR [--half-window 7] [--control]
needs: numpy, opencv-python-headless (as ../shared/peers/paper_numpy.py; see its README)
"""
import argparse
import os

import cv2
import numpy as np


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("raw")
    ap.add_argument("corrected")
    ap.add_argument("--half-window", type=int, default=7)
    ap.add_argument("--control", action="store_true")
    a = ap.parse_args()
    names = sorted(n for n in os.listdir(a.raw) if n.lower().endswith((".jpg", ".jpeg", ".png", ".tif", ".tiff")))
    disc = lambda d: cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (d, d))
    k6, k10, k25 = disc(13), disc(21), disc(51)
    dots = []
    for n in names:
        raw = cv2.imread(os.path.join(a.raw, n)).astype(np.int16)
        d = (raw[..., 2] - np.maximum(raw[..., 0], raw[..., 1])) > 40
        d[:24] = False
        dots.append(cv2.dilate(d.astype(np.uint8), k6) > 0)
    scores = []
    for i, n in enumerate(names):
        c = cv2.imread(os.path.join(a.corrected, n))
        if c is None:
            continue
        c = c.astype(np.float32)
        others = np.zeros_like(dots[0])
        for j in range(max(0, i - a.half_window), min(len(names), i + a.half_window + 1)):
            if j != i:
                others |= dots[j]
        own = cv2.dilate(dots[i].astype(np.uint8), k25) > 0
        all_dots = cv2.dilate(others.astype(np.uint8) | own.astype(np.uint8), k10) > 0
        region = others & ~own
        region[:30] = False
        if a.control:
            region = np.roll(region, 170, axis=0) & ~all_dots
            region[:30] = False
        if region.sum() < 50:
            continue
        weight = (~all_dots).astype(np.float32)
        weight[:30] = 0
        background = cv2.GaussianBlur(c * weight[..., None], (0, 0), 25) / np.maximum(
            cv2.GaussianBlur(weight, (0, 0), 25)[..., None], 1e-3
        )
        smooth = cv2.GaussianBlur(c, (0, 0), 3)
        scores.append(np.abs(smooth - background)[region].mean())
    s = np.array(scores)
    kind = "control (no stain)" if a.control else "stain"
    print(f"{a.corrected}: {kind} mean {s.mean():.3f}, 90th percentile {np.percentile(s, 90):.3f}, {len(s)} photos")


if __name__ == "__main__":
    main()
