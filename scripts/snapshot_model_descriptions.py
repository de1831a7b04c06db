"""Write a JSON digest of the modelDescription of every FMU in a folder (variables with
causality, variability, type, unit, range, start, description; default experiment; units;
output dependencies). ``tests/data/model_descriptions_before_issue8.json`` was made with it
from the FMUs built before the declarations moved onto the cores; ``tests/test_declarations.py``
compares today's FMUs with it.

    python scripts/snapshot_model_descriptions.py fmus/ > digest.json
"""

from __future__ import annotations

import json
import sys
import zipfile
from pathlib import Path

from cosim.run.model_digest import digest_model_description


def main(folder: str) -> None:
    out = {}
    for fmu in sorted(Path(folder).glob("*.fmu")):
        with zipfile.ZipFile(fmu) as z:
            out[fmu.stem] = digest_model_description(z.read("modelDescription.xml"))
    print(json.dumps(out, indent=1, sort_keys=True))


if __name__ == "__main__":
    main(sys.argv[1])
