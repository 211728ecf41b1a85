"""Running ccx (single-threaded) and reading what it prints into the .dat file."""

import os
import re
import shutil
import subprocess
import time

import numpy as np

# ccx reads its thread counts from these; the validation runs share two cores with other work.
SINGLE_THREAD = {"OMP_NUM_THREADS": "1", "CCX_NPROC_STIFFNESS": "1",
                 "CCX_NPROC_EQUATION_SOLVER": "1", "CCX_NPROC_RESULTS": "1",
                 "NUMBER_OF_CPUS": "1"}


class CcxError(RuntimeError):
    pass


def ccx_binary():
    return shutil.which("ccx")


def run(deck_text, directory, job):
    """Writes DIRECTORY/JOB.inp, runs ccx on it and returns the wall time [s].

    Raises CcxError with the tail of the log when ccx fails or prints *ERROR.
    """
    os.makedirs(directory, exist_ok=True)
    with open(os.path.join(directory, job + ".inp"), "w") as f:
        f.write(deck_text)
    env = dict(os.environ, **SINGLE_THREAD)
    log_path = os.path.join(directory, job + ".log")
    start = time.monotonic()
    with open(log_path, "w") as log:
        result = subprocess.run([ccx_binary(), "-i", job], cwd=directory, env=env,
                                stdout=log, stderr=subprocess.STDOUT, check=False)
    elapsed = time.monotonic() - start
    with open(log_path) as log:
        text = log.read()
    if result.returncode != 0 or "*ERROR" in text:
        tail = "\n".join(text.splitlines()[-15:])
        raise CcxError(f"ccx {job} in {directory} failed (exit {result.returncode}):\n{tail}")
    return elapsed


def _fortran_float(token):
    """Fortran drops the E of three-digit exponents: '-4.987683-108' means -4.987683E-108."""
    try:
        return float(token)
    except ValueError:
        return float(re.sub(r"(\d)([+-]\d{3})$", r"\1E\2", token))


_BLOCK = re.compile(r"displacements \(vx,vy,vz\) for set (\S+) and time\s+(\S+)")


def read_displacements(dat_path, node_count):
    """The displacement blocks of *NODE PRINT: a list of (time [s], (node_count, 3) array [m]).

    Assumes the printed set holds nodes 1..node_count, which is how the decks number the body.
    """
    with open(dat_path) as f:
        text = f.read()
    parts = _BLOCK.split(text)
    frames = []
    # split() yields [before, set, time, body, set, time, body, ...]
    for i in range(1, len(parts), 3):
        t = float(parts[i + 1])
        values = np.zeros((node_count, 3))
        seen = 0
        for line in parts[i + 2].splitlines():
            fields = line.split()
            if len(fields) != 4 or not fields[0].isdigit():
                if seen:
                    break
                continue
            values[int(fields[0]) - 1] = [_fortran_float(v) for v in fields[1:]]
            seen += 1
        if seen != node_count:
            raise CcxError(f"{dat_path}: block at t = {t} has {seen} nodes, expected {node_count}")
        frames.append((t, values))
    return frames


def read_eigenfrequencies(dat_path):
    """The frequencies [Hz] of the eigenvalue table of a *FREQUENCY step, in mode order."""
    with open(dat_path) as f:
        text = f.read()
    table = text.split("E I G E N V A L U E   O U T P U T", 1)[1]
    table = table.split("P A R T I C I P A T I O N", 1)[0]
    frequencies = []
    for line in table.splitlines():
        fields = line.split()
        if len(fields) == 5 and fields[0].isdigit():
            frequencies.append(float(fields[3]))  # cycles per time
    return np.array(frequencies)
