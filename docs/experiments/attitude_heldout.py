"""The issue's attitude targets on held-out synthetic drives, as a car team would run them: each bag's IMU
rest attitude from its standing phase (`cone-perception imu-rest BAG --seconds 2`), then `replay` in
each attitude mode with `--imu-rest` set to it, scored against /cones_gt and /attitude_gt.

    for s in 311 312 313; do
      cone-perception synth bag --seed $s --seconds 10 --stand 2 --out /tmp/ho/jit$s
      cone-perception synth bag --seed $s --seconds 10 --stand 2 --car-motion --out /tmp/ho/car$s
      cone-perception synth bag --seed $s --seconds 10 --stand 2 --no-jitter --out /tmp/ho/flat$s
    done
    .venv/bin/python docs/experiments/attitude_heldout.py /tmp/ho/jit31? /tmp/ho/car31? /tmp/ho/flat31?

`--modes fixed,image,...` limits the modes. Prints one row per bag and mode: recall within 15 m, median error 0-4 / 4-7 / 7-15 / 15-25 m, median |pitch|
and |roll| error, the attitude's cost per frame. Writes each replay's summary to BAG_MODE.json.
"""
import json
import subprocess
import sys
from pathlib import Path

CLI = [str(Path(sys.executable).parent / "cone-perception")]
MODES = tuple(m for m in ("fixed", "image", "imu", "fused") if m in (sys.argv[sys.argv.index("--modes") + 1].split(",") if "--modes" in sys.argv else "fixed,image,imu,fused"))


def rest(bag: str) -> str:
    out = subprocess.run(CLI + ["imu-rest", bag, "--seconds", "2", "--json"], check=True, capture_output=True, text=True).stdout
    p, r = json.loads(out)["imu_rest_deg"]
    return f"{p},{r}"


def replay(bag: str, mode: str, imu_rest: str) -> dict:
    js = Path(f"{bag}_{mode}.json")
    subprocess.run(CLI + ["replay", bag, "--calib", f"{bag}_calib.yaml", "--gt-topic", "/cones_gt", "--attitude", mode,
                          f"--imu-rest={imu_rest}", "--json", str(js), "--force", "--no-progress"],
                   check=True, capture_output=True, text=True)
    return json.loads(js.read_text())


def main(bags: list[str]) -> None:
    print("| bag | `--imu-rest` | mode | recall < 15 m | 0-4 m | 4-7 m | 7-15 m | 15-25 m | pitch / roll err (deg) | attitude ms |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for bag in (b.rstrip("/") for b in bags):
        r = rest(bag)
        for mode in MODES:
            s = replay(bag, mode, r)
            loc = s["localisation"]
            g = [loc["groups"][k] for k in ("near 0-4 m", "mid 4-7 m", "far 7-15 m")]
            recall = sum(x["n_matched"] for x in g) / max(sum(x["n_true"] for x in g), 1)
            att = loc.get("attitude", {})
            err = (f"{att['median_abs_err_pitch_deg']:.3f} / {att['median_abs_err_roll_deg']:.3f}"
                   if att.get("median_abs_err_pitch_deg") is not None else "-")
            ms = s["stages"].get("attitude", {}).get("median_ms")
            print(f"| {Path(bag).name} | {r} | {mode} | {recall:.3f} | " + " | ".join(f"{x['median_err_m']:.3f}" for x in g)
                  + f" | {loc['extra_groups']['15-25 m']['median_err_m']:.3f} | {err} | " + (f"{ms:.2f}" if ms else "-") + " |",
                  flush=True)


if __name__ == "__main__":
    args = sys.argv[1:]
    if "--modes" in args:  # --modes fixed,image: only these
        del args[args.index("--modes"):args.index("--modes") + 2]
    main(args)
