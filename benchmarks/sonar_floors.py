"""One sonar's floor chips of the shared real chips, with their MANIFEST rows, as a chip folder of their own (links,
no copies), for `sasmi split` and `sasmi calibrate --real`.

    python benchmarks/sonar_floors.py DATA SONAR OUT      (e.g. ../shared/data/sonar-chips sassed runs/sassed)
"""
import csv
import os
import sys

data, sonar, out = sys.argv[1:]
rows = [r for r in csv.DictReader(open(f"{data}/MANIFEST.csv")) if r["scene_group"].startswith(sonar)]
if not rows:
    sys.exit(f"{data}/MANIFEST.csv: no scene_group starts with {sonar!r}")
os.makedirs(f"{out}/seafloor", exist_ok=True)
for r in rows:
    link = f"{out}/{r['file']}"
    if not os.path.lexists(link):
        os.symlink(os.path.abspath(f"{data}/{r['file']}"), link)
with open(f"{out}/MANIFEST.csv", "w", newline="") as f:
    writer = csv.DictWriter(f, fieldnames=list(rows[0]))
    writer.writeheader()
    writer.writerows(rows)
print(f"{len(rows)} {sonar} chips in {out}")
