#!/usr/bin/env python3
"""Build pgrf's built-in camera profiles (crates/noise/profiles/*.json) from the
published calibration numbers in ../shared/data/profiles.

Run from the repository root: python3 tools/make_profiles.py
The output is committed; this script documents where each number comes from.
"""
import json
import os

SRC = os.path.join("..", "shared", "data", "profiles")
DST = os.path.join("crates", "noise", "profiles")

# ELD's synthesis code maps normalised images to DN with saturation_level =
# 16383 - 800 for every camera; its fits are expressed on that scale.
ELD_DN_RANGE = 16383 - 800

CAMERAS = {
    "SonyA7S2": ("sony-a7s2", "Sony", "ILCE-7SM2"),
    "NikonD850": ("nikon-d850", "Nikon", "D850"),
    "CanonEOS70D": ("canon-eos70d", "Canon", "EOS 70D"),
    "CanonEOS700D": ("canon-eos700d", "Canon", "EOS 700D"),
    "CanonEOS5D4": ("canon-eos5d4", "Canon", "EOS 5D Mark IV"),
}


def fit(d):
    return {"slope": d["slope"], "bias": d["bias"], "sigma": d["sigma"]}


def eld_block(p):
    prof = p["Profile-1"]
    return {
        "tukey_shapes": p["G_shape"],
        "tukey_scale": fit(prof["G_scale"]),
        "gauss_scale": fit(prof["g_scale"]),
        "row_scale": fit(prof["R_scale"]),
        "color_bias": p.get("color_bias", []),
    }


def main():
    os.makedirs(DST, exist_ok=True)
    for eld_name, (name, make, model) in CAMERAS.items():
        p = json.load(open(os.path.join(SRC, f"ELD_{eld_name}_params.json")))
        prof = {
            "schema": 1,
            "name": name,
            "make": make,
            "model": model,
            "source": f"ELD release (Vandermode/ELD, MIT): {eld_name}_params",
            "units": "All noise values are in DN on a scale where white - black = dn_range. "
            "K is the system gain in DN per electron. Scale fits are natural-log-linear in K: "
            "ln(sigma) = slope * ln(K) + bias + N(0, sigma_fit^2).",
            "dn_range": ELD_DN_RANGE,
            "black": None,
            "k_per_iso": None,
            "k_min": p["Kmin"],
            "k_max": p["Kmax"],
            "eld": eld_block(p),
            "per_iso": [],
            "dark_current": None,
        }
        if eld_name == "SonyA7S2":
            pmn = json.load(open(os.path.join(SRC, "PMN_SonyA7S2_per_iso.json")))
            ble = json.load(open(os.path.join(SRC, "PMN_SonyA7S2_darkshading_BLE.json")))
            cols = pmn["columns"]
            rows = []
            for r in pmn["rows"]:
                d = dict(zip(cols, r))
                rows.append({
                    "iso": int(d["iso"]),
                    "k": d["K"],
                    "tukey_lambda": d["tukey_lambda"],
                    "sigma_tukey": d["sigma_tukey_read"],
                    "sigma_gauss": d["sigma_gaussian_read"],
                    "sigma_row": d["sigma_row"],
                    "black_level_error": ble.get(str(int(d["iso"])), 0.0),
                })
            prof["source"] += (
                "; per-ISO table from PMN (megvii-research/PMN, Apache-2.0): K = 9.563e-4 x ISO, "
                "Tukey/Gaussian read, row sigma, and the measured black-level error by ISO"
            )
            prof["dn_range"] = pmn["white_level"] - pmn["black_level"]
            prof["black"] = pmn["black_level"]
            prof["k_per_iso"] = 9.563e-4
            prof["per_iso"] = rows
        with open(os.path.join(DST, f"{name}.json"), "w") as f:
            json.dump(prof, f, indent=1)
            f.write("\n")
        print("wrote", name)


if __name__ == "__main__":
    main()
