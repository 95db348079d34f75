"""The issue's attitude targets on held-out synthetic drives, as a car team would run them: each bag's IMU
rest attitude from its standing phase (`cone-perception imu-rest BAG --seconds 2`), then `replay` in
each attitude mode with `--imu-rest` set to it, scored against /cones_gt and /attitude_gt.

    for s in 331 332 333; do
      cone-perception synth bag --seed $s --seconds 10 --stand 2 --out /tmp/ho3/jit$s
      cone-perception synth bag --seed $s --seconds 10 --stand 2 --car-motion --out /tmp/ho3/car$s
      cone-perception synth bag --seed $s --seconds 10 --stand 2 --no-jitter --out /tmp/ho3/flat$s
    done
    .venv/bin/python docs/experiments/attitude_heldout.py /tmp/ho3/jit33? /tmp/ho3/flat33? [--modes fixed,image,fused]
    .venv/bin/python docs/experiments/attitude_heldout.py /tmp/ho3/jit33? --modes image --far-rows 384,576

Prints one row per bag and mode: recall within 15 m, median error 0-4 / 4-7 / 7-15 / 15-25 m, median
|pitch| and |roll| error, the attitude stage's median ms and the end-to-end median ms per frame.
Writes each replay's summary to BAG_MODE.json (BAG_MODE_far.json with --far-rows).
"""
import argparse
import json
import subprocess
import sys
from pathlib import Path

CLI = [str(Path(sys.executable).parent / "cone-perception")]
MODES = ("fixed", "image", "imu", "fused")


def rest(bag: str) -> str:
    out = subprocess.run(CLI + ["imu-rest", bag, "--seconds", "2", "--json"], check=True, capture_output=True, text=True).stdout
    p, r = json.loads(out)["imu_rest_deg"]
    return f"{p},{r}"


def replay(bag: str, mode: str, imu_rest: str, far_rows: str | None, box_model: str = "auto",
           box_behaviour: str = "as-is", box_jitter: str | None = None, far_model: str | None = None) -> dict:
    js = Path(f"{bag}_{mode}{'_far' if far_rows else ''}{'' if box_model == 'auto' else '_' + box_model}"
              f"{'' if box_behaviour == 'as-is' else '_' + box_behaviour}{'' if box_jitter is None else '_j' + box_jitter}"
              f"{'' if far_model is None else '_fm' + Path(far_model).stem}.json")
    extra = (["--far-rows", far_rows] if far_rows else []) + (["--box-model", box_model] if box_model != "auto" else [])
    extra += ["--box-behaviour", box_behaviour] if box_behaviour != "as-is" else []
    extra += ["--box-jitter", box_jitter] if box_jitter is not None else []
    extra += ["--far-model", far_model] if far_model is not None else []
    subprocess.run(CLI + ["replay", bag, "--calib", f"{bag}_calib.yaml", "--gt-topic", "/cones_gt", "--attitude", mode,
                          f"--imu-rest={imu_rest}", "--json", str(js), "--force", "--no-progress", *extra],
                   check=True, capture_output=True, text=True)
    return json.loads(js.read_text())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("bags", nargs="+")
    ap.add_argument("--modes", default=",".join(MODES), help="comma-separated attitude modes (default all four)")
    ap.add_argument("--far-rows", default=None, metavar="V0,V1",
                    help="replay --far-rows (default: replay's own, the calibration's strip; none: no far band)")
    ap.add_argument("--far-model", default=None, metavar="M", help="replay --far-model (band: the band's model in the strip)")
    ap.add_argument("--box-model", default="auto", choices=("auto", "model", "rendered"),
                    help="replay --box-model (default auto: the rendered table, these bags having /cones_gt)")
    ap.add_argument("--box-behaviour", default="as-is", choices=("as-is", "real"),
                    help="replay --box-behaviour (real: the detector's boxes behave as its box model says they do on "
                         "real frames; with --box-model auto the fit then reads them through that box model)")
    ap.add_argument("--box-jitter", default=None, metavar="F", help="replay --box-jitter (with --box-behaviour real)")
    args = ap.parse_args()
    modes = [m for m in args.modes.split(",") if m]
    label = (f" + far rows {args.far_rows}" if args.far_rows else "") + (f", far model {args.far_model}" if args.far_model else "") + ("" if args.box_model == "auto" else f", {args.box_model} box model")
    label += ", real boxes" if args.box_behaviour == "real" else ""
    label += f" (top spread {args.box_jitter})" if args.box_jitter is not None else ""
    print("| bag | `--imu-rest` | mode | recall < 15 m | 0-4 m | 4-7 m | 7-15 m | 15-25 m | pitch / roll err (deg) | attitude ms | end to end ms |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for bag in (b.rstrip("/") for b in args.bags):
        r = rest(bag)
        for mode in modes:
            s = replay(bag, mode, r, args.far_rows, args.box_model, args.box_behaviour, args.box_jitter, args.far_model)
            loc = s["localisation"]
            g = [loc["groups"][k] for k in ("near 0-4 m", "mid 4-7 m", "far 7-15 m")]
            recall = sum(x["n_matched"] for x in g) / max(sum(x["n_true"] for x in g), 1)
            att = loc.get("attitude", {})
            err = (f"{att['median_abs_err_pitch_deg']:.3f} / {att['median_abs_err_roll_deg']:.3f}"
                   if att.get("median_abs_err_pitch_deg") is not None else "-")
            ms = s["stages"].get("attitude", {}).get("median_ms")
            print(f"| {Path(bag).name} | {r} | {mode}{label} | {recall:.3f} | " + " | ".join(f"{x['median_err_m']:.3f}" for x in g)
                  + f" | {loc['extra_groups']['15-25 m']['median_err_m']:.3f} | {err} | " + (f"{ms:.2f}" if ms else "-")
                  + f" | {s['stages']['end_to_end']['median_ms']:.1f} |", flush=True)
            if s.get("attitude_fits"):
                print(f"<!-- {Path(bag).name} {mode}: {s['attitude_fits']} -->", flush=True)


if __name__ == "__main__":
    main()
