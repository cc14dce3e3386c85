"""Write a long synthetic 1080p video for the streaming-memory check of recordings.

A camera pans across a large seeded random texture (smoothed noise, so it compresses
like real footage rather than like white noise); H.264 ``ultrafast``, ``yuv420p``.

    python scripts/long_video.py outputs/long.mp4 --minutes 10 --fps 30
"""

from __future__ import annotations

import argparse
from fractions import Fraction
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from lburst.burst.io import atomic_path


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("out", type=Path)
    p.add_argument("--minutes", type=float, default=10.0)
    p.add_argument("--fps", type=int, default=30)
    p.add_argument("--size", default="1920x1080")
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args()
    import av

    width, height = (int(v) for v in args.size.split("x"))
    rng = np.random.default_rng(args.seed)
    texture = cv2.GaussianBlur(rng.integers(0, 256, (height * 2, width * 3, 3), dtype=np.uint8), (0, 0), 3)
    texture = cv2.normalize(texture, None, 0, 255, cv2.NORM_MINMAX)
    n = int(round(args.minutes * 60 * args.fps))
    span = texture.shape[1] - width
    with atomic_path(args.out) as tmp:
        with av.open(str(tmp), "w", format="mp4", options={"movflags": "+faststart"}) as container:
            stream = container.add_stream("libx264", rate=Fraction(args.fps))
            stream.width, stream.height, stream.pix_fmt = width, height, "yuv420p"
            stream.options = {"preset": "ultrafast", "crf": "23"}
            for j in tqdm(range(n), desc=args.out.name, unit="frame", mininterval=10):
                x = int(abs((j * 4) % (2 * span) - span))  # back and forth, 4 px per frame
                y = int((height / 2) * (1 + np.sin(j / 500)) / 2)
                frame = av.VideoFrame.from_ndarray(
                    np.ascontiguousarray(texture[y : y + height, x : x + width]), format="rgb24"
                )
                frame.pts = j
                for packet in stream.encode(frame):
                    container.mux(packet)
            for packet in stream.encode(None):
                container.mux(packet)
    print(f"{args.out}: {n} frames, {width}x{height}, {args.fps} fps, {args.out.stat().st_size / 1e6:.0f} MB")


if __name__ == "__main__":
    main()
