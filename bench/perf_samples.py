"""The samples of a `perf record` file, for bench/lpca_read_profile.py and lpca_phase_profile.py."""
import re
import subprocess


def perf_samples(data):
    """(time in s, symbol, shared object) of every sample in `data`, of every thread, by time."""
    out = subprocess.run(["perf", "script", "-i", data, "-F", "tid,time,ip,sym,dso"], capture_output=True, text=True,
                         check=True).stdout
    rows = []
    for line in out.splitlines():
        m = re.match(r"\s*\d+\s+([\d.]+):\s+[0-9a-f]+\s+(.*?)\s+\((.*)\)\s*$", line)
        if m:
            rows.append((float(m.group(1)), m.group(2), m.group(3)))
    rows.sort()
    return rows
