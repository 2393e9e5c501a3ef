import subprocess
import sys

import numpy as np

from sorjax import scenes
from sorjax.cli import main


def test_cli_calibrates_from_files(tmp_path, capsys):
    sc = scenes.two_spheres(f=700.0)
    files = []
    for i, o in enumerate(sc.outlines):
        f = tmp_path / f"view{i}.npy" if i else tmp_path / f"view{i}.txt"
        np.save(f, o) if f.suffix == ".npy" else np.savetxt(f, o)
        files.append(str(f))
    assert main(["calibrate", *files, "--method", "IIb"]) == 0
    out = capsys.readouterr().out
    fu = float(out.split("fu =")[1].split("px")[0])
    assert abs(fu - 700.0) < 0.07


def test_cli_bad_input_is_one_line_and_exit_2(tmp_path):
    bad = tmp_path / "bad.txt"
    bad.write_text("1 2\n3 nan\n")
    r = subprocess.run([sys.executable, "-m", "sorjax", "calibrate", str(bad), str(tmp_path / "missing.npy")],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 2
    assert "Traceback" not in r.stderr
    assert "sorjax: error:" in r.stderr and ("NaN" in r.stderr or "no such file" in r.stderr)
