"""Shared helpers of the benchmark scripts (not installed)."""
import json
import sys
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / 'results'


def dump(name: str, data: dict) -> Path:
    """Print ``data`` as JSON and write it to results/<name>.json."""
    RESULTS.mkdir(exist_ok=True)
    text = json.dumps(data, indent=2, default=float)
    print(text)
    out = RESULTS / f'{name}.json'
    out.write_text(text + '\n')
    print(f'written {out}', file=sys.stderr)
    return out
