"""What the study scripts share: the machine they ran on and updating a Markdown block."""

from __future__ import annotations

import os
from pathlib import Path


def machine() -> dict:
    """CPU model, core count and load average, to print next to every timing."""
    cpu = "unknown"
    for line in Path("/proc/cpuinfo").read_text().splitlines():
        if line.startswith("model name"):
            cpu = line.split(":", 1)[1].strip()
            break
    return {"cpu": cpu, "nproc": os.cpu_count(), "load": os.getloadavg()}


def write_block(doc: Path, name: str, text: str) -> None:
    """Replace the text between <!-- name:begin --> and <!-- name:end --> in `doc`."""
    begin, end = f"<!-- {name}:begin -->", f"<!-- {name}:end -->"
    body = doc.read_text() if doc.exists() else ""
    if begin in body and end in body:
        head, rest = body.split(begin, 1)
        _, tail = rest.split(end, 1)
        body = f"{head}{begin}\n{text}\n{end}{tail}"
    else:
        body += f"\n{begin}\n{text}\n{end}\n"
    doc.write_text(body)
    print(f"updated {doc} ({name})")
