"""Adversarial audit of the command line (issue #13): every verb, damaged inputs, bad options, output faults,
kills, concurrency. Not part of the test suite (it runs a few hundred CLI processes, ~10-20 min on 2 cores).

    .venv/bin/python tests/audit/run_audit.py [--jobs 2] [--only SUBSTRING] [--keep]

Every case runs ``python -m bsdfkit.cli.main …`` in a subprocess and is classified:

* ``ok`` — exit 0 and every announced output present (when the case expects success);
* ``error`` — exit 2 with exactly one line on stderr and no traceback (when the case expects an error);
* ``traceback`` — "Traceback" on stderr; ``hang`` — no exit within the time limit;
* ``partial`` — a temporary (``.part``/``.staging``/``.old``/``.probe``) left behind, an output of a failed
  run present, an input changed, or a file that a replaced output folder held still there (a mixed set);
* ``silent`` — exit 0 where an error was expected (bad input accepted);
* ``refused`` — an error where success was expected; ``cryptic`` — a failure that is not one line / exit 2;
* ``misleading`` — one clean error line that lacks a word of the case's ``mentions`` (the file, line, field or
  value that is the real cause); a success whose case has ``mentions`` must print a warning line with them; for
  the issue-26 command cases of :func:`command_cases`, a line that does not name its cause (:data:`CAUSES`) or
  whose after-check fails.

Full disks are a 256 KiB tmpfs and read-only folders a read-only bind mount when ``mount`` works (root);
otherwise those cases are skipped. Prints one line per non-ok/error case and a table per class.
"""
from __future__ import annotations

import argparse
import codecs
import contextlib
import gzip
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections import Counter
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
LEFTOVER = (".part", ".staging", ".old", ".probe")
#: the console command itself (bsdfkit_console: answers Ctrl-C from its first moment)
CLI = [sys.executable, "-m", "bsdfkit_console"]


@dataclass
class Case:
    name: str
    argv: list[str]
    expect: str = "error"  # "ok", "error" or "either" (a clean success or a clean one-line error)
    outputs: list[Path] = field(default_factory=list)  # must exist on success, must not on failure
    inputs: list[Path] = field(default_factory=list)  # must be unchanged afterwards
    timeout: float = 120.0
    kill: tuple[int, float] | None = None  # (signal, seconds after start), then a rerun without --force
    concurrent: bool = False  # run argv twice at once: exactly one must succeed
    cwd: Path | None = None
    absent: list[Path] = field(default_factory=list)  # must not exist afterwards (a replaced folder's old files)
    group: str = ""  # the class of the case in the summary table
    #: words the stderr line must contain (the cause named: file, line, field, found value); an error line
    #: without one of them is ``misleading``; on success, a warning line with them must be there (else ``silent``)
    mentions: list[str] = field(default_factory=list)
    quiet: bool = False  # a success that must print nothing on stderr (a fit that matches its data is not flagged)


# ---------------------------------------------------------------------------------------------- fixtures
SCENE = """[cavity]
radius_mm = 35.0
height_mm = 43.0
[wall]
reflectance = 0.90
[base]
reflectance = 0.90
[leds]
count = 4
pitch_mm = 20.0
emitter_radius_mm = 1.0
distribution = "lambertian"
power_W = 1.0
{extra_leds}
[top]
kind = "exit"
[trace]
lanes = 512
"""

RECIPE = """[recipe]
name = "audit"
measurement = "{measurement}"
[reductions]
budget_incidence_deg = 45.0
eta_mc = 0.94
iterations = 7
[exports]
interactions = ["bibs"]
sides = ["reflection"]
formats = ["zemax"]
tolerance = 0.05
[fits]
bsdf_model = "lambert+gaussian"
emission_model = "split-gaussian"
emission_incidence_deg = 45.0
led_peak_nm = 450.1
led_fwhm_nm = 22.9
fallback_flux_W = [0.058, 0.472]
"""


#: with --fork, cases run in children forked from this process after the verbs are imported (a cold start of
#: the command costs seconds on a loaded machine); kill and concurrency cases always start fresh processes
FORK = False


def _run_forked(argv: list[str], timeout: float, cwd: Path | None) -> tuple[int | None, str, str]:
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        pid = os.fork()
        if pid == 0:  # the child: the command line's main() with its own stdout/stderr
            code = 70
            try:
                os.dup2(out.fileno(), 1)
                os.dup2(err.fileno(), 2)
                sys.stdout = open(1, "w", closefd=False)
                sys.stderr = open(2, "w", closefd=False)
                if cwd is not None:
                    os.chdir(cwd)
                from bsdfkit.cli.main import main as cli_main
                try:
                    code = cli_main(argv)
                except SystemExit as exc:  # argparse
                    code = exc.code if isinstance(exc.code, int) else 2
                except BaseException:
                    import traceback
                    traceback.print_exc()
                    code = 1
                sys.stdout.flush()
                sys.stderr.flush()
            finally:
                os._exit(code)
        deadline = time.monotonic() + timeout
        status = None
        while time.monotonic() < deadline:
            done, status = os.waitpid(pid, os.WNOHANG)
            if done:
                break
            time.sleep(0.05)
        else:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            status = None
        out.seek(0)
        err.seek(0)
        text_out, text_err = out.read().decode(errors="replace"), err.read().decode(errors="replace")
    code = None if status is None else os.waitstatus_to_exitcode(status)
    return code, text_out, text_err


def run_cli(argv: list[str], timeout: float, cwd: Path | None = None) -> tuple[int | None, str, str]:
    if FORK:
        return _run_forked(argv, timeout, cwd)
    try:
        p = subprocess.run(CLI + argv, capture_output=True, text=True, timeout=timeout, cwd=cwd,
                           errors="replace")
        return p.returncode, p.stdout, p.stderr
    except subprocess.TimeoutExpired as exc:
        return None, "", (exc.stderr or b"").decode(errors="replace") if isinstance(exc.stderr, bytes) else ""


def make_fixtures(work: Path) -> dict[str, Path]:
    """Valid inputs of every kind, made with the toolkit itself and the repository's test data."""
    sys.path.insert(0, str(ROOT / "tests"))
    from conftest import tiny_gonio, tiny_plan  # the suite's small raw export

    from bsdfkit.simulation import virtual_goniometer as virtual
    f: dict[str, Path] = {}
    gonio = tiny_gonio()
    export = virtual.simulate_scan(virtual.cl830_truth(gonio), tiny_plan(), gonio, seed=1)
    f["raw"] = work / "fx" / "raw"
    virtual.write_raw_export(export, f["raw"])
    f["nc"] = work / "fx" / "scan.nc"
    code, _, err = run_cli(["ingest", str(f["raw"]), "-o", str(f["nc"])], 300)
    assert code == 0, err
    f["scene"] = work / "fx" / "scene.toml"
    f["scene"].write_text(SCENE.format(extra_leds=""))
    f["rays"] = work / "fx" / "rays.txt"
    f["rays"].write_text("\n".join(f"{x} 0 0 0 0 1 0.25" for x in (-10, -5, 5, 10)) + "\n")
    f["scene_rays"] = work / "fx" / "scene_rays.toml"
    f["scene_rays"].write_text(SCENE.format(extra_leds=f'ray_file = "{f["rays"]}"').replace("count = 4\n", "")
                               .replace("pitch_mm = 20.0\n", "").replace("emitter_radius_mm = 1.0\n", "")
                               .replace('distribution = "lambertian"\n', ""))
    f["recipe"] = work / "fx" / "recipe.toml"
    f["recipe"].write_text(RECIPE.format(measurement=f["raw"]))
    f["table"] = work / "fx" / "budget.json"
    f["table"].write_text(json.dumps({"power": {"B_bibs": 10.9, "F_bibs": 6.5, "B_biys": 26.3, "F_biys": 26.9,
                                                 "B_yiys": 45.0, "F_yiys": 48.0}}))
    f["zemax"] = ROOT / "tests" / "data" / "golden" / "zemax_lambert_brdf.bsdf"
    f["tracepro"] = ROOT / "tests" / "data" / "golden" / "tracepro_lambert_table.txt"
    f["asap"] = ROOT / "tests" / "data" / "golden" / "asap_lambert.txt"
    radiant = ROOT / "tests" / "data" / "ansys-radiant-zemax-bsdf"
    f["radiant"] = radiant / "radiant_imaging_sphere_planesymmetric_BRDF.bsdf"
    f["spectrum"] = ROOT / "tests" / "data" / "benkner-led-spectra" / "white_3000K.ISD"
    f["csv_table"] = work / "fx" / "table.csv"
    f["csv_table"].write_text("theta_i,theta_s,phi_s,brdf\n" + "".join(
        f"0,{t},0,{0.3183:.4f}\n" for t in range(0, 90, 5)))
    # Excel's "Unicode text" export of the same table: UTF-16LE with a byte-order mark, tabs, CRLF
    f["excel_table"] = work / "fx" / "table_excel.txt"
    f["excel_table"].write_bytes(codecs.BOM_UTF16_LE + f["csv_table"].read_text().replace(",", "\t")
                                 .replace("\n", "\r\n").encode("utf-16-le"))
    # the plate of a phosphor top: written by the toolkit from the Table-2 constants
    from bsdfkit.raytrace.plate import PhosphorPlate
    table2 = {"bibs_reflection": 0.109, "bibs_transmission": 0.054, "biys_reflection": 0.263,
              "biys_transmission": 0.257, "yiys_reflection": 0.457, "yiys_transmission": 0.471}
    f["plate"] = work / "fx" / "plate.json"
    PhosphorPlate.constant(table2, name="audit").save(f["plate"])
    f["scene_plate"] = work / "fx" / "scene_plate.toml"
    phosphor = f'kind = "phosphor"\nplate = "{f["plate"]}"'
    f["scene_plate"].write_text(SCENE.format(extra_leds="").replace('kind = "exit"', phosphor))
    return f


# ----------------------------------------------------------------------------------------- damaged inputs
def damaged_variants(path: Path) -> dict[str, bytes]:
    data = path.read_bytes()
    gz = data[:2] == b"\x1f\x8b"
    text_like = not gz and b"\x00" not in data[:4096]
    out = {
        "empty": b"",
        "binary": bytes(range(256)) * 8,
        "nul": data[: len(data) // 2] + b"\x00" * 64 + data[len(data) // 2:],
        "truncated": data[: max(1, len(data) // 3)],
        "latin1": gzip.compress(gzip.decompress(data).replace(b"0", b"\xe9", 3)) if gz
        else data.replace(b"e", b"\xe9", 3),
    }
    if gz:
        out["gzip_corrupt"] = data[:20] + bytes(b ^ 0x5A for b in data[20:60]) + data[60:]
        out["gzip_truncated"] = data[: len(data) // 2]
    if not text_like:
        out["first_bytes"] = data[:10]
        return out
    text = data.decode("utf-8-sig", "replace")
    # encodings a careful user expects to be read like UTF-8 (Excel's "Unicode text" is UTF-16LE + BOM)
    out["utf16"] = text.encode("utf-16")
    out["utf16le_bom"] = codecs.BOM_UTF16_LE + text.encode("utf-16-le")
    out["utf16be_bom"] = codecs.BOM_UTF16_BE + text.encode("utf-16-be")
    out["utf16le_nobom"] = text.encode("utf-16-le")
    out["utf32"] = text.encode("utf-32")
    out["utf8_bom"] = codecs.BOM_UTF8 + text.encode("utf-8")
    out["crlf"] = text.replace("\r\n", "\n").replace("\n", "\r\n").encode()
    # truncations: the last line cut inside its last number, the last line lost
    body = data.rstrip(b"\r\n")
    out["cut_number"] = body[:-1]
    out["last_line_lost"] = body[: body.rfind(b"\n") + 1]
    return out


def input_cases(work: Path, f: dict[str, Path]) -> list[Case]:
    cases: list[Case] = []
    dmg = work / "damaged"
    dmg.mkdir()

    def variants(kind: str, src: Path, suffix: str):
        for label, data in damaged_variants(src).items():
            p = dmg / f"{kind}_{label}{suffix}"
            p.write_bytes(data)
            yield label, p

    out = dmg / "o"
    for label, p in variants("scene", f["scene"], ".toml"):
        cases.append(Case(f"trace scene {label}", ["trace", str(p), "--rays", "1000", "-o", str(out / f"t_{label}.nc")],
                          outputs=[out / f"t_{label}.nc"], inputs=[p]))
        cases.append(Case(f"sweep scene {label}", ["sweep", str(p), "--param", "wall.reflectance=0.8", "--rays", "1000",
                                                    "-o", str(out / f"s_{label}.nc")], outputs=[out / f"s_{label}.nc"]))
    for label, p in variants("rays", f["rays"], ".txt"):
        s = dmg / f"scene_rays_{label}.toml"
        s.write_text(f["scene_rays"].read_text().replace(str(f["rays"]), str(p)))
        cases.append(Case(f"trace ray file {label}", ["trace", str(s), "--rays", "1000"]))
    for label, p in variants("plate", f["plate"], ".json"):
        s = dmg / f"scene_plate_{label}.toml"
        s.write_text(f["scene_plate"].read_text().replace(str(f["plate"]), str(p)))
        cases.append(Case(f"trace plate {label}", ["trace", str(s), "--rays", "1000"]))
    for label, p in variants("recipe", f["recipe"], ".toml"):
        cases.append(Case(f"run recipe {label}", ["run", str(p), "-o", str(out / f"run_{label}")],
                          outputs=[out / f"run_{label}"], timeout=300))
    for label, p in variants("table", f["table"], ".json"):
        cases.append(Case(f"budget table {label}", ["budget", "--table", str(p), "--eta-mc", "0.9"]))
    for kind in ("zemax", "tracepro", "asap", "radiant", "csv_table"):
        suffix = f[kind].suffix
        for label, p in variants(kind, f[kind], suffix):
            cases.append(Case(f"read {kind} {label}", ["read", str(p)]))
            o = out / f"ing_{kind}_{label}.nc"
            cases.append(Case(f"ingest {kind} {label}", ["ingest", str(p), "-o", str(o)], outputs=[o]))
            o2 = out / f"conv_{kind}_{label}.bsdf"
            side = ["--side", "reflection"] if kind in ("tracepro", "asap") else []  # a Zemax file holds one side
            cases.append(Case(f"convert {kind} {label}", ["convert", str(p), "--to", "zemax", *side, "-o", str(o2)],
                              outputs=[o2]))
    for label, p in variants("nc", f["nc"], ".nc"):
        cases.append(Case(f"info nc {label}", ["info", str(p)]))
        cases.append(Case(f"tis nc {label}", ["tis", str(p), "--incidence", "45"]))
        o = out / f"exp_{label}.bsdf"
        cases.append(Case(f"export nc {label}", ["export", str(p), "--to", "zemax", "--interaction", "bibs",
                                                  "-o", str(o)], outputs=[o]))
    # raw exports: the manifest and a scan file damaged
    for member in ("manifest.toml", "dark.csv.gz"):
        src = f["raw"] / member
        if not src.exists():
            continue
        for label, data in damaged_variants(src).items():
            folder = dmg / f"raw_{member.split('.')[0]}_{label}"
            shutil.copytree(f["raw"], folder)
            (folder / member).write_bytes(data)
            o = out / f"raw_{member.split('.')[0]}_{label}.nc"
            cases.append(Case(f"ingest raw {member} {label}", ["ingest", str(folder), "-o", str(o)], outputs=[o]))
    scans = sorted((f["raw"] / "scans").glob("*")) if (f["raw"] / "scans").is_dir() else []
    if scans:
        first = scans[0]
        for label, data in damaged_variants(first).items():
            folder = dmg / f"raw_scan_{label}"
            shutil.copytree(f["raw"], folder)
            (folder / "scans" / first.name).write_bytes(data)
            o = out / f"raw_scan_{label}.nc"
            cases.append(Case(f"ingest raw scan {label}", ["ingest", str(folder), "-o", str(o)], outputs=[o]))
    for label, p in variants("spectrum", f["spectrum"], ".ISD"):
        cases.append(Case(f"color spectrum {label}", ["color", str(p)]))
    for case in cases:
        label = case.name.rsplit(" ", 1)[-1]
        if label == "latin1":
            case.expect = "either"  # vendor files in Latin-1 may be read as such
        elif label in ENCODED_ALIKE and not case.name.startswith("read csv_table"):
            case.expect = "ok"  # the same text in another encoding: read like UTF-8 (`read` takes vendor files)
        elif label == "last_line_lost" or (label == "cut_number" and not case.name.startswith(CUT_DETECTABLE)):
            case.expect = "either"  # a whole line lost is detectable only where the layout says so
    return cases


#: variants that hold the original text in another encoding or line-end convention
ENCODED_ALIKE = ("utf16", "utf16le_bom", "utf16be_bom", "utf16le_nobom", "utf32", "utf8_bom", "crlf")
#: inputs whose layout makes a number cut at the end of the file detectable (numeric tables, fixed formats)
CUT_DETECTABLE = ("read tracepro", "ingest tracepro", "convert tracepro", "read zemax", "ingest zemax",
                  "convert zemax", "read asap", "ingest asap", "convert asap", "read radiant", "ingest radiant",
                  "convert radiant", "read csv_table", "ingest csv_table", "convert csv_table", "trace ray file",
                  "color spectrum", "trace plate", "budget table")


# ----------------------------------------------------------------------------------------------- options
BAD_NUMBERS = ("0", "-1", "nan", "inf", "-inf", "1e308", "abc", "1e12")


def option_cases(work: Path, f: dict[str, Path]) -> list[Case]:
    o = work / "opts"
    o.mkdir()
    scene, nc, raw, table, csv = (str(f[k]) for k in ("scene", "nc", "raw", "table", "csv_table"))
    # (verb argv with {} for the value, values that are valid)
    specs = {
        "trace --rays": (["trace", scene, "--rays", "{}"], {"1e12"} - {"1e12"}),
        "trace --seed": (["trace", scene, "--rays", "1000", "--seed", "{}"], {"0"}),
        "trace --chunk": (["trace", scene, "--rays", "1000", "--chunk", "{}"], set()),
        "trace --lanes": (["trace", scene, "--rays", "1000", "--lanes", "{}"], set()),
        "sweep --rays": (["sweep", scene, "--param", "wall.reflectance=0.8", "--rays", "{}", "--no-plots", "-o",
                          str(o / "sw{}.nc")], set()),
        "sweep --seed": (["sweep", scene, "--param", "wall.reflectance=0.8", "--rays", "1000", "--seed", "{}",
                          "--no-plots", "-o", str(o / "sws{}.nc")], {"0"}),
        "sweep --chunk": (["sweep", scene, "--param", "wall.reflectance=0.8", "--rays", "1000", "--chunk", "{}",
                           "--no-plots", "-o", str(o / "swc{}.nc")], set()),
        "sweep --workers": (["sweep", scene, "--param", "wall.reflectance=0.8", "--rays", "1000", "--workers", "{}",
                             "--no-plots", "-o", str(o / "sww{}.nc")], set()),
        "sweep --param count": (["sweep", scene, "--param", "wall.reflectance=0.8:0.9:{}", "--rays", "1000",
                                 "--no-plots", "-o", str(o / "swp{}.nc")], set()),
        "sweep --param value": (["sweep", scene, "--param", "wall.reflectance={}", "--rays", "1000",
                                 "--no-plots", "-o", str(o / "swv{}.nc")], {"0"}),
        "budget --eta-mc": (["budget", "--table", table, "--eta-mc", "{}"], {"0"}),  # η_MC in [0, 1]
        "budget --iterations": (["budget", "--table", table, "--eta-mc", "0.9", "--iterations", "{}"], set()),
        "budget --incidence": (["budget", nc, "--incidence", "{}", "--eta-mc", "0.9"], set()),
        "tis --incidence": (["tis", nc, "--incidence", "{}"], set()),
        "tis --band": (["tis", nc, "--incidence", "45", "--band", "{}", "500"], set()),
        "simulate --seed": (["simulate", "--seed", "{}", "-o", str(o / "sim{}")], {"0"}),
        "export --symmetry-tolerance": (["export", nc, "--to", "zemax", "--interaction", "bibs",
                                         "--symmetry-tolerance", "{}", "-o", str(o / "e{}.bsdf")], set()),
        # (a tolerance of 0 demands exact plane symmetry: a 1e-15 deviation is refused, rightly)
        "export --zero-azimuth": (["export", nc, "--to", "tracepro", "--interaction", "bibs", "--zero-azimuth",
                                   "{}", "-o", str(o / "z{}.txt")], {"0", "-1"}),
        "export --wavelength-nm": (["export", nc, "--to", "tracepro", "--interaction", "bibs", "--wavelength-nm",
                                    "{}", "-o", str(o / "w{}.txt")], set()),
        "export --wavelength-um": (["export", nc, "--to", "tracepro", "--interaction", "bibs", "--wavelength-um",
                                    "{}", "-o", str(o / "wu{}.txt")], set()),
        "export --temperature-k": (["export", nc, "--to", "tracepro", "--interaction", "bibs", "--temperature-k",
                                    "{}", "-o", str(o / "tk{}.txt")], set()),
        "export --incidences": (["export", nc, "--to", "zemax", "--interaction", "bibs", "--incidences", "{}",
                                 "-o", str(o / "inc{}.bsdf")], set()),
        "convert --wavelength": (["convert", nc, "--to", "zemax", "--interaction", "bibs", "--wavelength", "{}",
                                  "-o", str(o / "cw{}.bsdf")], set()),
        "convert --tis-tolerance": (["convert", nc, "--to", "zemax", "--interaction", "bibs", "--side", "reflection",
                                     "--tis-tolerance", "{}", "-o", str(o / "ct{}.bsdf")], {"0"}),
        "convert --relative-std": (["convert", csv, "--to", "zemax", "--relative-std", "{}", "-o",
                                    str(o / "cr{}.bsdf")], set()),  # a relative uncertainty is > 0
        "ingest --relative-std": (["ingest", csv, "--relative-std", "{}", "-o", str(o / "ir{}.nc")], set()),
        "ingest --wavelength": (["ingest", csv, "--wavelength", "{}", "-o", str(o / "iw{}.nc")], set()),
        # the table states its incidences: --incidence is refused whatever its value
        "ingest --incidence": (["ingest", csv, "--incidence", "{}", "-o", str(o / "ii{}.nc")], set()),
        "ingest --phi-i": (["ingest", csv, "--phi-i", "{}", "-o", str(o / "ip{}.nc")], {"0", "-1"}),
        "fit bsdf --incidence": (["fit", "bsdf", nc, "--interaction", "bibs", "--side", "reflection", "--incidence",
                                  "{}"], set()),
        "fit spectrum --maxiter": (["fit", "spectrum", str(f["spectrum"]), "--maxiter", "{}"], set()),
        "fit spectrum --split-nm": (["fit", "spectrum", str(f["spectrum"]), "--split-nm", "{}"], set()),
    }
    cases = []
    for name, (argv, valid) in specs.items():
        for value in BAD_NUMBERS:
            tag = value.replace("-", "m").replace(".", "p")
            args = [a.replace("{}", value) if a == "{}" or "={}" in a or ":{}" in a else a.replace("{}", tag)
                    for a in argv]
            outs = [Path(a) for a in args if a.startswith(str(o))]
            cases.append(Case(f"option {name} {value}", args, "ok" if value in valid else "error", outputs=outs))
    return cases


# -------------------------------------------------------------------------------------------- output faults
def output_cases(work: Path, f: dict[str, Path], mounts: dict[str, Path]) -> list[Case]:
    o = work / "outf"
    o.mkdir()
    afile = o / "a_file"
    afile.write_text("x")
    adir = o / "a_dir"
    adir.mkdir()
    scene, nc, raw = str(f["scene"]), str(f["nc"]), str(f["raw"])
    writers = {
        "ingest": lambda out: ["ingest", raw, "-o", out],
        "export": lambda out: ["export", nc, "--to", "zemax", "--interaction", "bibs", "-o", out],
        "convert": lambda out: ["convert", str(f["zemax"]), "--to", "tracepro", "-o", out],
        "trace": lambda out: ["trace", scene, "--rays", "2000", "-o", out],
        "sweep": lambda out: ["sweep", scene, "--param", "wall.reflectance=0.8,0.9", "--rays", "2000", "-o", out],
        "simulate": lambda out: ["simulate", "-o", out],
        "run": lambda out: ["run", str(f["recipe"]), "-o", out],
    }
    cases = []
    for verb, build in writers.items():
        t = 600 if verb in ("run", "simulate") else 180
        cases.append(Case(f"{verb} -o is a folder", build(str(adir)) if verb not in ("run", "simulate")
                          else build(str(afile)), timeout=t))
        cases.append(Case(f"{verb} -o under a file", build(str(afile / "x.out")), timeout=t))
        for label, root in mounts.items():
            target = root / f"{verb}.out"
            cases.append(Case(f"{verb} -o on {label}", build(str(target)), outputs=[target], timeout=t))
        # --force onto an input
        inp = {"ingest": raw, "export": nc, "convert": str(f["zemax"]), "trace": scene, "sweep": scene,
               "run": str(f["recipe"].parent)}.get(verb)
        if inp:
            copy_dir = o / f"self_{verb}"
            copy_dir.mkdir()
            src = Path(inp)
            local = copy_dir / src.name
            (shutil.copytree if src.is_dir() else shutil.copy)(src, local)
            args = build(str(local if verb != "ingest" else local / "manifest.toml"))
            args = [str(local) if a == inp else a for a in args]
            if verb == "run":
                args = ["run", str(local / "recipe.toml"), "-o", str(local)]
            cases.append(Case(f"{verb} --force onto its input", args + ["--force"],
                              inputs=[p for p in ([local] if local.is_file() else local.rglob("*")) if p.is_file()],
                              timeout=t))
        # existing output without --force
        exists = o / f"exists_{verb}.out"
        exists.write_text("previous")
        if verb in ("run", "simulate"):
            exists.unlink()
            exists.mkdir()
            (exists / "summary.json").write_text("{}")
            (exists / "README.md").write_text("previous")
        cases.append(Case(f"{verb} output exists, no --force", build(str(exists)),
                          inputs=[exists] if exists.is_file() else [exists / "summary.json"], timeout=t))
    # a folder that is the output as a whole: never mixed with other files
    for verb in ("simulate", "run"):
        t = 600
        crowded = o / f"crowded_{verb}"
        crowded.mkdir()
        (crowded / "notes.txt").write_text("someone else's")
        cases.append(Case(f"{verb} into a non-empty folder, no --force", writers[verb](str(crowded)),
                          inputs=[crowded / "notes.txt"], timeout=t))
        replaced = o / f"replaced_{verb}"
        replaced.mkdir()
        (replaced / "notes.txt").write_text("someone else's")
        first = "manifest.toml" if verb == "simulate" else "summary.json"
        cases.append(Case(f"{verb} --force into a non-empty folder", writers[verb](str(replaced)) + ["--force"],
                          "ok", outputs=[replaced / first], absent=[replaced / "notes.txt"], timeout=t))
    return cases


def kill_cases(work: Path, f: dict[str, Path]) -> list[Case]:
    k = work / "kills"
    k.mkdir()
    scene = str(f["scene"])
    cases = []
    long_jobs = {
        "trace": lambda out: ["trace", scene, "--rays", "300000000", "-o", out],
        "sweep": lambda out: ["sweep", scene, "--param", "wall.reflectance=0.5:0.9:40", "--rays", "3000000",
                              "-o", out],
        "simulate": lambda out: ["simulate", "-o", out],
        "run": lambda out: ["run", str(f["recipe"]), "-o", out],
        "ingest": lambda out: ["ingest", str(ROOT / "measurements" / "cl830-synthetic"), "-o", out],
    }
    for verb, build in long_jobs.items():
        for sig, name in ((signal.SIGINT, "SIGINT"), (signal.SIGTERM, "SIGTERM"), (signal.SIGKILL, "SIGKILL")):
            for delay in (5.0, 20.0):
                out = k / f"{verb}_{name}_{int(delay)}.out"
                cases.append(Case(f"kill {verb} {name} at {delay:g}s", build(str(out)), "ok", outputs=[out],
                                  kill=(sig, delay), timeout=900))
    # a signal while the command still imports its libraries (the first second)
    for verb in ("trace", "ingest", "simulate"):
        for sig, name in ((signal.SIGINT, "SIGINT"), (signal.SIGTERM, "SIGTERM")):
            for delay in (0.3, 1.0):
                out = k / f"{verb}_{name}_early_{delay:g}.out"
                cases.append(Case(f"kill {verb} {name} at {delay:g}s", long_jobs[verb](str(out)), "ok",
                                  outputs=[out], kill=(sig, delay), timeout=900))
    # a sweep on a local dask cluster: workers and their semaphores must go with the command, silently
    for sig, name in ((signal.SIGINT, "SIGINT"), (signal.SIGTERM, "SIGTERM")):
        out = k / f"sweep_workers_{name}.out"
        cases.append(Case(f"kill sweep --workers 2 {name} at 30s",
                          long_jobs["sweep"](str(out)) + ["--workers", "2"], "ok", outputs=[out],
                          kill=(sig, 30.0), timeout=900))
    return cases


def concurrency_cases(work: Path, f: dict[str, Path]) -> list[Case]:
    c = work / "conc"
    c.mkdir()
    return [
        Case("two ingest writers", ["ingest", str(f["raw"]), "-o", str(c / "a.nc")], "ok", outputs=[c / "a.nc"],
             concurrent=True),
        Case("two export writers", ["export", str(f["nc"]), "--to", "zemax", "--interaction", "bibs", "-o",
                                    str(c / "b.bsdf")], "ok", outputs=[c / "b.bsdf"], concurrent=True),
        Case("two trace writers", ["trace", str(f["scene"]), "--rays", "2000", "-o", str(c / "t.nc")], "ok",
             outputs=[c / "t.nc"], concurrent=True),
        Case("two sweep writers", ["sweep", str(f["scene"]), "--param", "wall.reflectance=0.8", "--rays", "2000",
                                   "-o", str(c / "s.nc")], "ok", outputs=[c / "s.nc"], concurrent=True),
        Case("two simulate writers", ["simulate", "-o", str(c / "sim")], "ok", outputs=[c / "sim"],
             concurrent=True, timeout=600),
    ]


# ------------------------------------------------------------------ issue 26: commands, tracer and outputs
#: what the one error line of a case must say (the cause named), and checks after the run: (case name) ->
#: (substrings of stderr, a callable returning a problem or None). A case whose line misses a substring, or
#: whose check fails, is "misleading" (kept apart from the Case fields, which other audits extend).
CAUSES: dict[str, tuple[tuple[str, ...], object]] = {}
#: bind mounts made by these cases, unmounted when the audit ends
_MOUNTED: list[Path] = []


def _unmount_all() -> None:
    for point in reversed(_MOUNTED):
        subprocess.run(["umount", str(point)], capture_output=True)


def judge_cause(case: Case, verdict: str, err: str) -> tuple[str, str] | None:
    """("misleading", why) when a case of :data:`CAUSES` does not name its cause or its check fails."""
    if case.name not in CAUSES:
        return None
    needles, check = CAUSES[case.name]
    if verdict in ("error", "ok"):
        missing = [n for n in needles if n not in err]
        if missing:
            return "misleading", f"the line does not say {missing!r}: {err.strip()[-300:]}"
        problem = check() if callable(check) else None
        if problem:
            return "misleading", problem
    return None


def command_cases(work: Path, f: dict[str, Path], mounts: dict[str, Path]) -> list[Case]:
    """Issue 26 (commands/tracer/outputs): degenerate beam widths, worker failures, closed lossless cavities,
    read-only and bind-mounted output folders, --force onto an input of every verb, usage errors, long names,
    a full disk. Every expected error must name its cause (:data:`CAUSES`)."""
    import atexit

    d = work / "i26"
    d.mkdir()
    cases: list[Case] = []

    def add(case: Case, *needles: str, check=None) -> None:
        cases.append(case)
        CAUSES[case.name] = (needles, check)

    base = SCENE.format(extra_leds="")
    for fwhm in ("1e-06", "1e-300"):
        sc = d / f"narrow_{fwhm}.toml"
        sc.write_text(base.replace('distribution = "lambertian"', f"fwhm_deg = {fwhm}"))
        add(Case(f"i26 trace beam fwhm_deg = {fwhm}", ["trace", str(sc), "--rays", "2000"], "ok"))
    sc = d / "wide.toml"
    sc.write_text(base.replace('distribution = "lambertian"', "fwhm_deg = 180"))
    add(Case("i26 trace beam fwhm_deg = 180", ["trace", str(sc), "--rays", "2000"]), "leds.fwhm_deg", "180")
    # a closed cavity whose second point costs more than MAX_TRACE_EVENTS: it fails in its worker
    closed = d / "closed.toml"
    closed.write_text(base.replace('kind = "exit"', 'kind = "lambertian"\nreflectance = 0.5\ntransmittance = 0.5')
                      + "max_events = 300000\n")
    out = d / "workers.nc"
    add(Case("i26 sweep --workers 2 with one failing point",
             ["sweep", str(closed), "--param", "base.reflectance=0.9,0.999999", "--rays", "1000000", "--workers", "2",
              "--no-plots", "-o", str(out)], timeout=300),
        "1 sweep point(s) failed, written as NaN", "base.reflectance=0.999999", "MAX_TRACE_EVENTS")
    add(Case("i26 sweep --workers 2 with a value out of range",
             ["sweep", str(f["scene"]), "--param", "cavity.height_mm=10,-5", "--rays", "2000", "--workers", "2",
              "--no-plots", "-o", str(d / "range.nc")], outputs=[d / "range.nc"], timeout=300), "cavity.height_mm")
    # white closed cavity under a plate that loses nothing: formerly > 100 s at 2e6 rays; 60 s is a hang here
    plate = ['kind = "phosphor"', "[top.plate]", "theta_i_deg = [0.0, 90.0]"]
    for inter, r in (("bibs", 1.0), ("biys", 0.0), ("yiys", 1.0)):
        for side, v in (("reflection", r), ("transmission", 0.0)):
            plate += [f"[top.plate.{inter}.{side}]", f"tis = [{v}, {v}]", 'distribution = {kind = "lambertian"}']
    lossless = d / "lossless.toml"
    lossless.write_text(SCENE.format(extra_leds="").replace("reflectance = 0.90", "reflectance = 1.0")
                        .replace('[top]\nkind = "exit"', "[top]\n" + "\n".join(plate)))
    add(Case("i26 trace closed lossless cavity under a plate, 2e6 rays", ["trace", str(lossless), "--rays", "2000000"],
             timeout=60), "no ray can ever leave or be absorbed", "LOSSLESS_MAX_EVENTS")
    # read-only (555) empty output folder: refused, and still 555 afterwards
    for verb in ("trace", "sweep"):
        ro = d / f"ro_{verb}"
        ro.mkdir()
        ro.chmod(0o555)
        argv = (["trace", str(f["scene"]), "--rays", "2000"] if verb == "trace" else
                ["sweep", str(f["scene"]), "--param", "wall.reflectance=0.8,0.9", "--rays", "2000"])
        add(Case(f"i26 {verb} -o into an empty read-only folder", argv + ["-o", str(ro / "x.nc")],
                 outputs=[ro / "x.nc"]), "not writable", "mode 555",
            check=lambda ro=ro: None if (ro.stat().st_mode & 0o777) == 0o555 else
            f"the folder's mode changed to {ro.stat().st_mode & 0o777:o}")
    # --force onto an input, for every verb that writes a file (same path and a hard link)
    inputs = {"fit bsdf": (f["nc"], ["fit", "bsdf", "{i}", "--interaction", "bibs", "--side", "reflection"]),
              "fit reflectance": (f["spectrum"], ["fit", "reflectance", "{i}"]),
              "ingest": (f["csv_table"], ["ingest", "{i}"]), "convert": (f["zemax"], ["convert", "{i}", "--to",
                                                                                        "tracepro"]),
              "export": (f["nc"], ["export", "{i}", "--to", "zemax", "--interaction", "bibs"]),
              "trace": (f["scene"], ["trace", "{i}", "--rays", "2000"]),
              "sweep": (f["scene"], ["sweep", "{i}", "--param", "wall.reflectance=0.8,0.9", "--rays", "2000"])}
    for verb, (src, argv) in inputs.items():
        for how in ("same path", "hard link"):
            folder = d / f"self_{verb.replace(' ', '_')}_{how.replace(' ', '_')}"
            folder.mkdir()
            local = folder / src.name
            shutil.copy(src, local)
            target = local
            if how == "hard link":
                target = folder / ("link" + src.suffix)
                os.link(local, target)
            add(Case(f"i26 {verb} --force onto its input ({how})",
                     [a.format(i=local) for a in argv] + ["-o", str(target), "--force"], inputs=[local]),
                "output would overwrite an input of this command", "refused even with --force")
    add(Case("i26 fit without a sub-verb", ["fit"]), "no sub-verb given", "spectrum, bsdf, reflectance")
    # a valid 250-byte output name (its temporary name must fit too), and a 256-byte one (too long)
    for size, expect in ((250, "ok"), (256, "error")):
        name = d / ("n" * (size - 3) + ".nc")
        add(Case(f"i26 trace -o a {size}-byte name", ["trace", str(f["scene"]), "--rays", "2000", "-o", str(name)],
                 expect, outputs=[name] if expect == "ok" else []),
            *(() if expect == "ok" else ("file name too long",)))
    # a full disk (the tmpfs of fault_mounts): the line says space and names the file
    if "a full disk" in mounts:
        target = mounts["a full disk"] / "i26_map.nc"
        mapped = d / "map.toml"
        mapped.write_text(base + "[tallies]\nirradiance_map = true\nmap_bins = 512\n")
        add(Case("i26 trace -o onto a full disk", ["trace", str(mapped), "--rays", "2000", "-o", str(target)],
                 outputs=[target]), "no space left on device while writing i26_map.nc")
    # a writable bind mount of a folder of the same file system (os.path.ismount says False)
    src, dst = d / "bind_src", d / "bind_dst"
    src.mkdir()
    dst.mkdir()
    if subprocess.run(["mount", "--bind", str(src), str(dst)], capture_output=True).returncode == 0:
        if not _MOUNTED:
            atexit.register(_unmount_all)
        _MOUNTED.append(dst)
        for verb in ("trace", "sweep"):
            target = dst / f"{verb}.nc"
            argv = (["trace", str(f["scene"]), "--rays", "2000"] if verb == "trace" else
                    ["sweep", str(f["scene"]), "--param", "wall.reflectance=0.8,0.9", "--rays", "2000"])
            add(Case(f"i26 {verb} -o into a writable bind mount", argv + ["-o", str(target)], "ok",
                     outputs=[target]))
    return cases


def verb_smoke_cases(work: Path, f: dict[str, Path]) -> list[Case]:
    s = work / "smoke"
    s.mkdir()
    return [
        Case("help", ["--help"], "ok"),
        Case("no verb", [], "error"),
        Case("unknown verb", ["frobnicate"], "error"),
        Case("info raw", ["info", str(f["raw"])], "ok"),
        Case("info missing", ["info", str(s / "missing.nc")]),
        Case("tis nc", ["tis", str(f["nc"]), "--incidence", "45"], "ok"),
        Case("read zemax", ["read", str(f["zemax"])], "ok"),
        Case("read tracepro", ["read", str(f["tracepro"])], "ok"),
        Case("read asap", ["read", str(f["asap"])], "ok"),
        Case("read a folder", ["read", str(s)]),
        Case("ingest Excel unicode-text table", ["ingest", str(f["excel_table"]), "-o", str(s / "excel.nc")], "ok",
             outputs=[s / "excel.nc"]),
        Case("convert Excel unicode-text table", ["convert", str(f["excel_table"]), "--to", "zemax", "-o",
                                                  str(s / "excel.bsdf")], "ok", outputs=[s / "excel.bsdf"]),
        Case("budget table", ["budget", "--table", str(f["table"]), "--eta-mc", "0.9"], "ok"),
        Case("budget nothing", ["budget", "--eta-mc", "0.9"]),
        Case("trace ok", ["trace", str(f["scene"]), "--rays", "2000", "-o", str(s / "t.nc")], "ok",
             outputs=[s / "t.nc"]),
        Case("trace ray file ok", ["trace", str(f["scene_rays"]), "--rays", "2000"], "ok"),
        Case("color ok", ["color", str(f["spectrum"])], "ok"),
        Case("bench bad only", ["bench", "--only", "nope", "-o", str(s / "bench")]),
        Case("fit bsdf ok", ["fit", "bsdf", str(f["nc"]), "--interaction", "bibs", "--side", "reflection"], "ok",
             timeout=300),
        Case("scene missing", ["trace", str(s / "missing.toml")]),
        Case("scene is a folder", ["trace", str(s)]),
        Case("recipe missing", ["run", str(s / "missing.toml"), "-o", str(s / "r")]),
    ]


# --------------------------------------------------------------------------------------------- classify
def _long_table(path: Path, value, wavelengths=(450.0, 550.0, 650.0),
                header: str = "theta_i,theta_s,phi_s,wavelength,brdf", thetas=range(0, 90, 5)) -> Path:
    lines = [header]
    for lam in wavelengths:
        for th in thetas:
            for ph in range(0, 360, 30):
                lines.append(f"10,{th},{ph},{lam!r},{value(lam, th, ph)!r}")
    path.write_text("\n".join(lines) + "\n")
    return path


def plausibility_cases(work: Path, f: dict[str, Path]) -> list[Case]:
    """Issue #26: values and units a file contradicts, dark frames above the signal, physical line numbers,
    single-wavelength and exact fits, huge values; each judged by the words its line must hold."""
    import math

    s = work / "plausibility"
    s.mkdir()
    lam = lambda rho: (lambda la, th, ph: rho / math.pi)  # noqa: E731
    neg = _long_table(s / "neg.csv", lambda la, th, ph: -0.5 / math.pi)
    metres = _long_table(s / "metres.csv", lam(0.5), wavelengths=(4.5e-7, 5.5e-7, 6.5e-7))
    mixed = _long_table(s / "mixed.csv", lam(0.5), wavelengths=(450.0, 0.55, 650.0))
    zero = _long_table(s / "zero.csv", lambda la, th, ph: 0.0)
    huge = _long_table(s / "huge.csv", lambda la, th, ph: 1e308)
    mono = _long_table(s / "mono.csv", lam(0.8), wavelengths=(550.0,))
    white = _long_table(s / "white.csv", lam(1.0))
    rad = s / "rad.csv"
    rows = ["theta_i [deg],theta_s [deg],phi_s [deg],wavelength,brdf"]
    rows += [f"0.17,{0.1 * i!r},{0.5 * j!r},550,{0.5 / math.pi!r}" for i in range(16) for j in range(12)]
    rad.write_text("\n".join(rows) + "\n")
    # raw export: a comment between scan rows and a bad side on physical line 6; darks too bright at 10 and 20 s
    commented = s / "commented"
    shutil.copytree(f["raw"], commented)
    scan = commented / "scans" / "blue.csv.gz"
    lines = gzip.decompress(scan.read_bytes()).decode().splitlines()
    cells = lines[3].split(",")
    cells[4] = "sideways"
    lines = [lines[0], lines[1], "# operator note", "", lines[2], ",".join(cells)] + lines[4:]
    scan.write_bytes(gzip.compress(("\n".join(lines) + "\n").encode()))
    hot = s / "hot"
    shutil.copytree(f["raw"], hot)
    dark = hot / "dark.csv.gz"
    lines = gzip.decompress(dark.read_bytes()).decode().splitlines()
    out = [lines[0]]
    for line in lines[1:]:
        c = line.split(",")
        out.append(",".join(c[:2] + [str(int(float(x)) * 3) for x in c[2:]] if c[1] in ("10", "20") else c))
    dark.write_bytes(gzip.compress(("\n".join(out) + "\n").encode()))
    fit = ["--interaction", "elastic", "--side", "reflection", "--model", "lambert"]
    return [
        Case("ingest all-negative table", ["ingest", str(neg), "-o", str(s / "neg.nc")], outputs=[s / "neg.nc"],
             mentions=["neg.csv:2:", "'brdf'", "negative beyond noise"]),
        Case("ingest wavelengths in metres", ["ingest", str(metres), "-o", str(s / "m.nc")], outputs=[s / "m.nc"],
             mentions=["metres.csv:2:", "'wavelength'", "look like metres"]),
        Case("ingest um and nm mixed", ["ingest", str(mixed), "-o", str(s / "x.nc")], outputs=[s / "x.nc"],
             mentions=["mixed.csv:218:", "'wavelength'", "two units", "lines 218"]),
        Case("ingest radians under deg", ["ingest", str(rad), "-o", str(s / "r.nc")], outputs=[s / "r.nc"],
             mentions=["rad.csv:2:", "theta_s [deg]", "radians"]),
        Case("ingest all-zero table", ["ingest", str(zero), "-o", str(s / "z.nc")], outputs=[s / "z.nc"],
             mentions=["zero.csv:2:", "all zero"]),
        Case("tis huge values", ["tis", str(huge)], mentions=["huge.csv:2:", "'brdf'", "1e+308"]),
        Case("info raw comment line", ["info", str(commented)], mentions=["blue.csv.gz:6:", "sideways"]),
        Case("ingest dark above signal", ["ingest", str(hot), "-o", str(s / "hot.nc")], "ok",
             outputs=[s / "hot.nc"], mentions=["warning", "dark frames above the signal", "exposures 10, 20 s"]),
        Case("tis dark above signal", ["tis", str(hot), "--incidence", "45"], "ok",
             mentions=["bsdfkit tis: warning", "dark frames above the signal"]),
        Case("budget dark above signal", ["budget", str(hot), "--incidence", "45", "--eta-mc", "0.5"], "ok",
             mentions=["bsdfkit budget: warning", "dark frames above the signal"]),
        Case("fit bsdf single wavelength", ["fit", "bsdf", str(mono), *fit], "ok", timeout=300, quiet=True),
        Case("fit bsdf perfect white lambertian", ["fit", "bsdf", str(white), *fit], "ok", timeout=300, quiet=True),
    ]


# ---------------------------------------------------------------------------------- issue 44: outputs and inputs
#: the formats every writer knows (convert/export --to)
FORMATS = ("tracepro", "zemax", "asap", "bsdfxml", "speos", "speosbrdf", "lighttools")


def issue44_cases(work: Path, f: dict[str, Path]) -> list[Case]:
    """Issue #44: ``--force`` replaces only regular files (FIFO, folder, symlink outputs), a refused output is never
    left (non-physical sources, a failed TIS check), netCDF datasets checked on reading, messages that name the real
    cause, recipes out of range, the real BSDF XML files of the repository. Every input and output is inside the
    audit's folder (the FIFO is made with ``os.mkfifo`` there; no device node is touched)."""
    import math
    import stat

    import xarray as xr

    d = work / "i44"
    d.mkdir()
    cases: list[Case] = []

    def add(case: Case, *needles: str, check=None) -> None:
        cases.append(case)
        CAUSES[case.name] = (needles, check)

    # 1. --force replaces only regular files: a FIFO, a folder, a symlink (to a file here) as the output
    kept = d / "kept.txt"
    kept.write_text("the symlink's target, never to be replaced\n")
    writers = {
        "convert": lambda out: ["convert", str(f["zemax"]), "--to", "tracepro", "-o", out],
        "export": lambda out: ["export", str(f["nc"]), "--to", "zemax", "--interaction", "bibs", "-o", out],
        "ingest": lambda out: ["ingest", str(f["csv_table"]), "-o", out],
        "fit bsdf": lambda out: ["fit", "bsdf", str(f["nc"]), "--interaction", "bibs", "--side", "reflection",
                                 "-o", out],
    }
    for verb, build in writers.items():
        tag = verb.replace(" ", "_")
        fifo = d / f"{tag}.fifo"
        os.mkfifo(fifo)
        add(Case(f"i44 {verb} --force onto a FIFO", build(str(fifo)) + ["--force"], timeout=60),
            check=lambda p=fifo: None if stat.S_ISFIFO(os.lstat(p).st_mode) else f"{p} is no longer a FIFO")
        folder = d / f"{tag}_dir"
        folder.mkdir()
        (folder / "inside.txt").write_text("x")
        add(Case(f"i44 {verb} --force onto a folder", build(str(folder)) + ["--force"], timeout=120,
                 inputs=[folder / "inside.txt"]),
            check=lambda p=folder: None if p.is_dir() and not p.is_symlink() else f"{p} is no longer a folder")
        link = d / f"{tag}.link"
        link.symlink_to(kept)
        add(Case(f"i44 {verb} --force onto a symlink", build(str(link)) + ["--force"], timeout=120,
                 inputs=[kept]),
            check=lambda p=link: None if p.is_symlink() else f"{p} is no longer a symlink")
    # the main job: an output folder that is a symlink (to a folder here) or a regular file
    runs = d / "runs"  # apart: a run's staging folder is judged beside its output
    runs.mkdir()
    real = runs / "run_real"
    real.mkdir()
    (real / "notes.txt").write_text("someone else's")
    run_link = runs / "run_link"
    run_link.symlink_to(real, target_is_directory=True)
    add(Case("i44 run --force into a symlinked folder", ["run", str(f["recipe"]), "-o", str(run_link), "--force"],
             timeout=300, inputs=[real / "notes.txt"]),
        check=lambda: None if run_link.is_symlink() and real.is_dir() else "the symlink or its folder was replaced")
    run_file = runs / "run_file"
    run_file.write_text("a regular file\n")
    add(Case("i44 run --force into a regular file", ["run", str(f["recipe"]), "-o", str(run_file), "--force"],
             timeout=300, inputs=[run_file]))

    # 2. a refused output is never left: a non-physical source (Lambertian, reflectance 1.5) to every format
    hot = _long_table(d / "hot.csv", lambda la, th, ph: 1.5 / math.pi, wavelengths=(550.0,))
    for fmt in FORMATS:
        fresh = d / f"hot_{fmt}.out"
        add(Case(f"i44 convert non-physical to {fmt}", ["convert", str(hot), "--to", fmt, "-o", str(fresh)],
                 outputs=[fresh]), "exceeds 1")
        earlier = d / f"hot_{fmt}_earlier.out"
        earlier.write_bytes(f"an earlier good {fmt} file\n".encode())
        add(Case(f"i44 convert non-physical to {fmt} --force over an earlier file",
                 ["convert", str(hot), "--to", fmt, "-o", str(earlier), "--force"], inputs=[earlier]), "exceeds 1",
            check=lambda p=earlier: leftovers([p]) or None)
    strict = d / "strict.bsdf"
    add(Case("i44 convert --tis-tolerance 1e-9", ["convert", str(f["radiant"]), "--to", "zemax", "--side",
                                                  "reflection", "--tis-tolerance", "1e-9", "-o", str(strict)],
             outputs=[strict]),
        "TIS check failed", check=lambda: f"{strict} exists" if strict.exists() else None)

    # 3. netCDF datasets written by other hands
    with xr.open_dataset(f["nc"]) as src:
        good = src.load()
    variants = {"negative": lambda ds: ds.assign(bsdf=-abs(ds["bsdf"]) - 1.0),
                "no bsdf": lambda ds: ds.drop_vars("bsdf"),
                "units 1/deg": lambda ds: ds.assign(bsdf=ds["bsdf"].assign_attrs(units="1/deg")),
                "1e300": lambda ds: ds.assign(bsdf=ds["bsdf"] * 0 + 1e300),
                "plain xarray": lambda ds: xr.Dataset({k: xr.DataArray(v.values, dims=v.dims)
                                                      for k, v in ds.data_vars.items()},
                                                     coords={k: xr.DataArray(v.values, dims=v.dims)
                                                             for k, v in ds.coords.items()})}
    words = {"negative": ("field 'bsdf", "negative"), "no bsdf": ("'bsdf'",), "units 1/deg": ("'bsdf'", "1/deg"),
             "1e300": ("field 'bsdf", "1e+300"), "plain xarray": ()}
    for label, change in variants.items():
        p = d / f"nc_{label.replace(' ', '_').replace('/', '_')}.nc"
        change(good.copy(deep=True)).to_netcdf(p)
        expect = "ok" if label == "plain xarray" else "error"
        conv = d / f"nc_{label.replace(' ', '_').replace('/', '_')}.bsdf"
        for verb, argv in (("tis", ["tis", str(p), "--incidence", "45"]), ("info", ["info", str(p)]),
                           ("fit bsdf", ["fit", "bsdf", str(p), "--interaction", "bibs", "--side", "reflection"]),
                           ("convert", ["convert", str(p), "--to", "zemax", "--interaction", "bibs", "--side",
                                        "reflection", "-o", str(conv)])):
            add(Case(f"i44 {verb} netCDF {label}", argv, expect, inputs=[p], timeout=300,
                     outputs=[conv] if verb == "convert" else []), *words[label])

    # 4. messages naming the real cause
    speos = ROOT / "tests" / "data" / "ansys-speos-anisotropicbsdf"
    nan = d / "nan.anisotropicbsdf"
    text = (speos / "test_13_planesymmetric_brdf_speos_reference.anisotropicbsdf").read_text()
    lines = text.splitlines(keepends=True)
    row = next(i for i, ln in enumerate(lines) if ln.startswith("5.0\t"))
    cells = lines[row].split("\t")
    cells[3] = "nan"
    lines[row] = "\t".join(cells)
    nan.write_text("".join(lines))
    add(Case("i44 read Speos file with a NaN", ["read", str(nan)]), f"nan.anisotropicbsdf:{row + 1}:", "not finite",
        "column 4")
    neg = d / "negative.csv"
    rows = ["theta_i,theta_s,phi_s,wavelength,brdf", "# measured 2026-01-01"]
    rows += [f"10,{th},{ph},550,{-0.2 if (th, ph) == (30, 60) else 0.1}" for th in range(0, 90, 5)
             for ph in range(0, 360, 30)]
    rows = rows[:2] + [ln.replace(",0.1", ",-0.1") for ln in rows[2:]]
    neg.write_text("\n".join(rows) + "\n")
    add(Case("i44 ingest negative table", ["ingest", str(neg), "-o", str(d / "neg.nc")], outputs=[d / "neg.nc"]),
        "negative.csv:3:", "'brdf'", "negative")
    metres = d / "metres.brdf"
    lines = (speos / "test_13_brdf_one_wavelength_speos.brdf").read_text().splitlines(keepends=True)
    assert lines[9].strip() == "550"
    lines[9] = "5.5e-07\n"
    metres.write_text("".join(lines))
    add(Case("i44 read Speos .brdf wavelength in metres", ["read", str(metres)]), "metres.brdf:10:", "metres")
    add(Case("i44 ingest Speos .brdf wavelength in metres", ["ingest", str(metres), "-o", str(d / "m.nc")],
             outputs=[d / "m.nc"]), "metres.brdf:10:", "metres")
    reflection = _long_table(d / "reflection.csv", lambda la, th, ph: 0.5 / math.pi, wavelengths=(550.0,))
    add(Case("i44 ingest --side transmission on reflection", ["ingest", str(reflection), "--side", "transmission",
                                                              "-o", str(d / "tr.nc")], outputs=[d / "tr.nc"]),
        "transmission", "only reflection")
    add(Case("i44 fit bsdf --side transmission on reflection",
             ["fit", "bsdf", str(reflection), "--interaction", "elastic", "--side", "transmission"], timeout=300),
        "--side", "transmission", "reflection")
    twice = _long_table(d / "twice.csv", lambda la, th, ph: 0.5 / math.pi, wavelengths=(550.0,),
                        header="theta_i,theta_s,phi_s,wavelength,brdf,brdf")
    twice.write_text("".join(ln + ",0.16\n" if i else ln + "\n"
                             for i, ln in enumerate(twice.read_text().splitlines())))
    add(Case("i44 ingest a value column twice", ["ingest", str(twice), "-o", str(d / "tw.nc")],
             outputs=[d / "tw.nc"]), "'brdf'", "column 5", "column 6")
    add(Case("i44 sweep --scheduler without a port",
             ["sweep", str(f["scene"]), "--param", "wall.reflectance=0.8", "--rays", "1000", "--scheduler",
              "127.0.0.1", "--no-plots", "-o", str(d / "sched.nc")], outputs=[d / "sched.nc"]),
        "--scheduler", "127.0.0.1")
    # (an unreachable scheduler at tcp://127.0.0.1:1 is not run: its 30 s timeout is a constant, no variable)

    # 5. a recipe out of range: refused in under 10 s
    shutil.copytree(ROOT / "fitting" / "scenes", d / "fitting" / "scenes")  # the recipe's scene, beside it
    recipe = (ROOT / "fitting" / "cl830.toml").read_text()
    recipe = recipe.replace('"../measurements/', f'"{ROOT / "measurements"}/')
    recipe = re.sub(r"figure_wavelength_nm = [0-9.]+", "figure_wavelength_nm = 2000", recipe)
    far = d / "fitting" / "cl830.toml"
    far.write_text(recipe)
    add(Case("i44 run recipe figure_wavelength_nm = 2000", ["run", str(far), "-o", str(d / "far")],
             outputs=[d / "far"], timeout=10), "figure_wavelength_nm", "2000", "[380, 780]")

    # 6. the real BSDF XML files of the repository
    xmls = sorted((ROOT / "tests" / "data" / "pyradiance-sample-bsdf").glob("*.xml"))
    xmls += sorted((ROOT / "tests" / "data" / "frads-bsdf").glob("*.xml"))
    for x in xmls:
        ing, conv = d / f"xml_{x.stem}.nc", d / f"xml_{x.stem}.xml"
        cases += [Case(f"i44 read XML {x.name}", ["read", str(x)], "ok", timeout=300),
                  Case(f"i44 ingest XML {x.name}", ["ingest", str(x), "-o", str(ing)], "ok", outputs=[ing],
                       timeout=300),
                  Case(f"i44 convert XML {x.name} to bsdfxml", ["convert", str(x), "--to", "bsdfxml", "-o", str(conv)],
                       "ok", outputs=[conv], timeout=300)]
    return cases


def _alive(entry: Path) -> bool:
    """A temporary named after a process that still runs (another case running at the same time): the process id
    is the first all-digit part of ``.NAME.PID.HEX.staging`` or ``.bsdfkit-PID.HEX.part``."""
    for part in re.split(r"[.-]", entry.name):
        if part.isdigit():
            try:
                os.kill(int(part), 0)
            except (ProcessLookupError, ValueError, OverflowError):
                return False
            except PermissionError:
                return True
            return True
    return False


def leftovers(paths: list[Path]) -> list[str]:
    found = []
    for p in paths:
        for folder in {p.parent, p} if p.is_dir() else {p.parent}:
            with contextlib.suppress(OSError):
                # exists() after _alive(): a case running at the same time may remove its temporary and exit
                # between the listing and the check of its process (a false "left behind" otherwise)
                found += [str(e) for e in folder.rglob("*")
                          if e.name.endswith(LEFTOVER) and not _alive(e) and e.exists()]
    return sorted(set(found))


def complete(out: Path) -> bool:
    """Whether an output that exists after a signal is whole: a run folder has its summary and every file the
    summary lists, a simulated measurement its manifest, a netCDF file opens and loads."""
    try:
        if out.is_dir():
            if (out / "summary.json").is_file():
                listed = json.loads((out / "summary.json").read_text(encoding="utf-8")).get("outputs", [])
                return all((out / name).is_file() for name in listed)
            return (out / "manifest.toml").is_file()
        import xarray as xr

        with xr.open_dataset(out) as ds:
            ds.load()
        return True
    except Exception:  # noqa: BLE001 - anything unreadable is not a complete output
        return False


def snapshot(paths: list[Path]) -> dict[Path, bytes | None]:
    return {p: p.read_bytes() if p.is_file() else None for p in paths}


def classify(case: Case, code: int | None, err: str) -> str:
    if code is None:
        return "hang"
    if "Traceback" in err:
        return "traceback"
    lines = [ln for ln in err.strip().splitlines() if ln.strip()]
    if code == 0:
        if case.expect == "error":
            return "silent"
        if case.mentions and not any(all(m in ln for m in case.mentions) for ln in lines):
            return "silent"  # a success that had to say something (a warning naming the cause) and did not
        if case.quiet and lines:
            return "misleading"  # a warning where nothing is wrong
        missing = [p for p in case.outputs if not p.exists()]
        return "partial" if missing else "ok"
    if code == 1 and len(lines) == 1 and lines[0].startswith("bsdfkit convert: TIS check failed"):
        # convert's designed result for a table whose TIS the target grid cannot hold (docs/exports.md): the
        # check reported and the table not moved to the output path, for the original file as for its re-encodings
        return "ok" if case.expect in ("ok", "either") else "error"
    if code == 2 and len(lines) == 1 and ": error: " in lines[0]:
        if any(p.exists() for p in case.outputs) and case.expect == "error":
            return "partial"
        if case.mentions and not all(m in lines[0] for m in case.mentions):
            return "misleading"  # one clean line that does not name the real cause
        return "error" if case.expect in ("error", "either") else "refused"
    return "cryptic"


def run_case(case: Case) -> tuple[str, str]:
    before = snapshot(case.inputs)
    if case.concurrent:
        procs = [subprocess.Popen(CLI + case.argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
                 for _ in range(2)]
        results = []
        for p in procs:
            try:
                _, e = p.communicate(timeout=case.timeout)
                results.append((p.returncode, e))
            except subprocess.TimeoutExpired:
                p.kill()
                results.append((None, ""))
        codes = sorted(r[0] for r in results if r[0] is not None)
        errs = " | ".join(r[1].strip() for r in results if r[1].strip())
        if len(codes) < 2:
            return "hang", errs
        if "Traceback" in errs:
            return "traceback", errs
        if codes != [0, 2]:
            return ("silent" if codes == [0, 0] else "cryptic"), f"exit codes {codes}: {errs}"
        verdict = "partial" if leftovers(case.outputs) else "ok"
        return verdict, errs
    if case.kill is not None:
        sig, delay = case.kill
        p = subprocess.Popen(CLI + case.argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                             preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
        time.sleep(delay)
        finished_early = p.poll() is not None
        sent = time.perf_counter()
        if not finished_early:
            p.send_signal(sig)
        try:
            _, err = p.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            p.kill()
            return "hang", f"no exit 30 s after {sig!r}"
        waited = time.perf_counter() - sent
        if "Traceback" in err:
            return "traceback", err[-400:]
        out = case.outputs[0]
        if not finished_early and p.returncode in (0, -sig, 128 + sig) and out.exists():
            # the signal came as the command finished (its handlers already gone, or the kill after the
            # final rename): nothing may be lost, so the output must be whole and nothing left behind
            left = leftovers(case.outputs)
            if not complete(out) or left:
                return "partial", f"exit {p.returncode} after the signal, output incomplete or {left}"
            return "ok", f"finished as the signal came (exit {p.returncode}); the output is complete"
        if not finished_early and sig != signal.SIGKILL and (
                p.returncode != 128 + sig or len(err.strip().splitlines()) != 1):
            return "cryptic", f"exit {p.returncode}, stderr not one line: {err.strip()[-300:]}"
        if not finished_early and waited > 2.0 and sig != signal.SIGKILL:
            return "hang", f"exit {waited:.1f} s after the signal"
        left = leftovers(case.outputs) if sig != signal.SIGKILL else []
        if finished_early:  # done before the signal: a complete output, and a rerun without --force is refused
            if p.returncode != 0 or not out.exists() or left:
                return "partial", f"finished before the signal: exit {p.returncode}, output {out.exists()}, {left}"
            code, _, err2 = run_cli(case.argv, case.timeout)
            lines = err2.strip().splitlines()
            if code == 2 and len(lines) == 1 and "exists" in lines[0]:
                return "ok", "finished before the signal; the rerun without --force is refused"
            return ("traceback" if "Traceback" in err2 else "cryptic"), f"rerun: exit {code}: {err2.strip()[-300:]}"
        if out.exists():
            return "partial", f"output present after the kill: {out}"
        if left:
            return "partial", f"left behind: {left}"
        code, _, err2 = run_cli(case.argv, case.timeout)  # rerun without --force
        if code != 0:
            return ("traceback" if "Traceback" in err2 else "refused"), f"rerun: exit {code}: {err2.strip()[-300:]}"
        left = leftovers(case.outputs)
        return ("partial", f"after rerun: {left}") if left else ("ok", f"signal after {delay:g}s, "
                                                                        f"exit in {waited:.2f}s")
    code, _, err = run_cli(case.argv, case.timeout, case.cwd)
    verdict = classify(case, code, err)
    judged = judge_cause(case, verdict, err)
    if judged is not None:
        verdict, err = judged
    changed = [str(p) for p, data in before.items() if (p.read_bytes() if p.is_file() else None) != data]
    if changed:
        return "partial", f"input changed: {changed}"
    left = leftovers(case.outputs)
    if left and verdict in ("ok", "error", "refused"):
        return "partial", f"left behind: {left}"
    mixed = [str(p) for p in case.absent if p.exists()]
    if mixed and verdict == "ok":
        return "partial", f"a replaced output folder still holds {mixed}"
    return verdict, err.strip()[-400:]


# -------------------------------------------------------------------------------------------------- main
@contextlib.contextmanager
def fault_mounts(work: Path):
    """A full disk (256 KiB tmpfs, filled) and a read-only folder (read-only bind mount), when mounting works."""
    mounts: dict[str, Path] = {}
    full, ro = work / "full", work / "ro"
    full.mkdir()
    ro.mkdir()
    try:
        if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=256k", "tmpfs", str(full)],
                          capture_output=True).returncode == 0:
            mounts["a full disk"] = full
            # filled to the last block: a 5 KB table fits in what 250 KB of filler leaves, and was then
            # (rightly) written, which the audit took for a silent failure
            with contextlib.suppress(OSError), open(full / "filler", "wb", buffering=0) as fh:
                while fh.write(b"\0" * 4096):
                    pass
        if subprocess.run(["mount", "--bind", "-o", "ro", str(ro), str(ro)], capture_output=True).returncode == 0:
            mounts["a read-only folder"] = ro
        yield mounts
    finally:
        for p in (full, ro):
            subprocess.run(["umount", str(p)], capture_output=True)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--only", action="append", default=None,
                    help="run only cases whose name contains this, or of this class (repeatable: any of them)")
    ap.add_argument("--keep", action="store_true", help="keep the work folder")
    ap.add_argument("--no-kills", action="store_true", help="skip the kill cases (the slowest)")
    ap.add_argument("--list", action="store_true", help="print how many cases each class holds, run none")
    ap.add_argument("--fork", action="store_true",
                    help="run the single-process cases in children forked after the imports (much faster)")
    args = ap.parse_args()
    # a stopped audit still unmounts its fault mounts and removes its work folder (the finally blocks below)
    signal.signal(signal.SIGTERM, lambda signum, frame: sys.exit(128 + signum))
    if args.fork:
        global FORK
        FORK = True
        import importlib

        from bsdfkit.cli.main import VERBS
        for verb in VERBS:
            importlib.import_module(f"bsdfkit.cli.{verb}")
        import jax  # noqa: F401  (imported, not initialised: forking stays safe)
    work = Path(tempfile.mkdtemp(prefix="bsdfkit-audit-"))
    started = time.time()
    try:
        f = make_fixtures(work)
        with fault_mounts(work) as mounts:
            cases = []
            for group, made in (("smoke", verb_smoke_cases(work, f)), ("inputs", input_cases(work, f)),
                                ("options", option_cases(work, f)), ("output faults", output_cases(work, f, mounts)),
                                ("concurrency", concurrency_cases(work, f)),
                                ("issue 26 commands", command_cases(work, f, mounts)),
                                ("plausibility", plausibility_cases(work, f)),
                                ("issue 44", issue44_cases(work, f)),
                                ("kills", [] if args.no_kills else kill_cases(work, f))):
                for case in made:
                    case.group = f"input {case.name.rsplit(' ', 1)[-1]}" if group == "inputs" else group
                cases += made
            if args.only:
                cases = [c for c in cases if any(o in c.name or o == c.group for o in args.only)]
            if args.list:
                for group, n in Counter(c.group for c in cases).items():
                    print(f"  {group:26s}{n:6d}")
                print(f"  {'all':26s}{len(cases):6d}")
                return 0
            serial = [c for c in cases if c.kill or c.concurrent]
            parallel = [c for c in cases if not (c.kill or c.concurrent)]

            def run_logged(case: Case) -> tuple[str, str]:
                verdict, detail = run_case(case)
                if verdict not in ("ok", "error"):  # as they come: a long audit's findings survive a stop
                    print(f"[{verdict}] {case.name}: {' '.join(detail.split())[:300]}", flush=True)
                return verdict, detail

            with ThreadPoolExecutor(max(1, args.jobs)) as pool:
                results = list(pool.map(run_logged, parallel))
            results += [run_logged(c) for c in serial]
            cases = parallel + serial
        tally = Counter(v for v, _ in results)
        verdicts = ("ok", "error", "traceback", "hang", "partial", "silent", "refused", "cryptic", "misleading")
        print(f"\n{len(cases)} cases in {time.time() - started:.0f} s; mounts: {sorted(mounts) or 'none'}")
        print(f"  {'class':26s}" + "".join(f"{v:>11s}" for v in verdicts))
        by_group = Counter((c.group, v) for c, (v, _) in zip(cases, results))
        for group in dict.fromkeys(c.group for c in cases):
            print(f"  {group:26s}" + "".join(f"{by_group.get((group, v), 0):11d}" for v in verdicts))
        print(f"  {'all':26s}" + "".join(f"{tally.get(v, 0):11d}" for v in verdicts))
        return 0 if set(tally) <= {"ok", "error"} else 1
    finally:
        _unmount_all()
        if args.keep:
            print(f"work folder kept: {work}")
        else:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
