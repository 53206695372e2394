"""How much photos differ in exposure and white balance, measured from the photos alone, against the truth.

Run: ``python benchmarks/exposure.py [--scenes wall object] [--size 480] [--settings 0.5:0.08 0.15:0.03 0.05:0.01
0:0]``

For each demo scene and each ``STOPS:WB`` setting, :func:`pytest_n2r.demo.phone_capture.write_phone_capture`
photographs the trajectory (exposure drawn in ±STOPS, white balance in 1 ± WB, blur and JPEG as a phone), and
:func:`pytest_n2r.data.exposure.measure_exposure` measures the training photos: ``spread`` (the whole capture)
and ``jump`` (neighbouring photos), both natural log, the ``residual`` a gain per photo leaves, and the RMS error
of the measured gains against the drawn ones (the phone multiplies linear light: the stored values scale by the
gain to the power 1/2.2). ``auto`` is what ``n2r fit --appearance auto`` decides
(:func:`pytest_n2r.fit.appearance.needs_appearance`). The fox (``../shared/scenes/fox``, 1/4 resolution, as
``benchmarks/field_fit.py`` fits it; no truth) is measured too when present. No fit: seconds.
Results: docs/scene-field-log.md.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

from pytest_n2r.data import ingest
from pytest_n2r.data.exposure import ExposureSpread, measure_exposure
from pytest_n2r.demo.phone_capture import PhoneSettings, write_phone_capture
from pytest_n2r.fit.appearance import needs_appearance

FOX = Path(__file__).resolve().parents[2] / "shared" / "scenes" / "fox" / "transforms.json"


def parse_setting(text: str) -> tuple[float, float]:
    """``"0.5:0.08"`` → (0.5 stops, 0.08 white balance)."""
    try:
        stops, wb = (float(x) for x in text.split(":"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected STOPS:WB, e.g. 0.5:0.08") from None
    return stops, wb


def row(name: str, setting: str, measured: ExposureSpread, error: float | None) -> str:
    def num(x: float | None) -> str:
        return "n/a" if x is None else f"{x:.4f}"

    return (f"| {name} | {setting} | {int(measured.measured.sum())} of {len(measured.names)} | {len(measured.pairs)} | "
            f"{num(measured.spread)} | {num(measured.jump)} | {num(measured.residual)} | {num(error)} | "
            f"{'on' if needs_appearance(measured) else 'off'} |")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="*", default=["wall", "object"])
    parser.add_argument("--size", type=int, default=480, help="longer side of the photos, pixels")
    parser.add_argument("--settings", nargs="+", type=parse_setting, metavar="STOPS:WB",
                        default=[(0.5, 0.08), (0.15, 0.03), (0.05, 0.01), (0.0, 0.0)])
    args = parser.parse_args(argv)
    print("| capture | ±stops : ±white balance | photos measured | pairs | spread | jump | residual | "
          "gain error (RMS) | auto |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name in args.scenes:
        for stops, wb in args.settings:
            with tempfile.TemporaryDirectory(prefix="n2r-exposure-") as tmp:
                photos = {p.path.name: p for p in write_phone_capture(
                    name, tmp, PhoneSettings(size=args.size, exposure_stops=stops, white_balance=wb))}
                views = ingest(tmp, downscale=1.0).train_views
            truth = np.array([np.log(photos[v.name].gain * np.array(photos[v.name].white_balance)) / 2.2
                              for v in views])
            measured = measure_exposure(views)
            ok = measured.measured
            error = None
            if ok.sum() >= 2:  # both in the gauge of the measured photos: their mean is 0
                truth_ok = truth[ok] - truth[ok].mean(axis=0)
                gains_ok = measured.log_gains[ok] - measured.log_gains[ok].mean(axis=0)
                error = float(np.sqrt(np.mean((gains_ok - truth_ok) ** 2)))
            print(row(name, f"{stops:g} : {wb:g}", measured, error), flush=True)
    if FOX.exists():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the fox transforms.json lists frames whose photos are absent
            fox = ingest(FOX, downscale=0.25)
        print(row("fox (1/4)", "a handheld video's", measure_exposure(fox.train_views), None))
    else:
        print(f"fox skipped: {FOX} is absent (it lives in ../shared beside the checkout)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
