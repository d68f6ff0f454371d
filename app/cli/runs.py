"""``deltadash runs compare ID ID ...``: runs' statistics side by side, as a table.

From a running server (``--url``, GET /api/runs/compare) or from a runs folder on this
machine (``--folder``, default the configured ``runs.folder``). ``--plot FILE`` also saves
the errors overlaid as a PNG (GET /api/runs/compare.png, or drawn here).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import urllib.error
import urllib.parse
import urllib.request
from pathlib import Path
from typing import Any


def add_parser(commands: argparse._SubParsersAction) -> argparse.ArgumentParser:
    runs = commands.add_parser("runs", help="look at recorded runs")
    actions = runs.add_subparsers(dest="action", required=True)
    compare = actions.add_parser("compare", help="two or more runs' statistics side by side")
    compare.add_argument("ids", nargs="+", metavar="ID", help="run ids (two or more)")
    where = compare.add_mutually_exclusive_group()
    where.add_argument("--url", help="a running server, e.g. http://127.0.0.1:8000")
    where.add_argument("--folder", type=Path, help="a runs folder (default: runs.folder)")
    token = os.environ.get("DELTADASH_TOKEN")
    compare.add_argument("--token", default=token, help="the server's token ($DELTADASH_TOKEN)")
    compare.add_argument("--plot", type=Path, help="also save the errors overlaid as this PNG")
    compare.add_argument("--json", action="store_true", help="print the table as JSON")
    compare.set_defaults(handler=run_compare)
    return runs


def _get(url: str, token: str | None) -> bytes:
    headers = {"authorization": f"Bearer {token}"} if token else {}
    request = urllib.request.Request(url, headers=headers)
    with urllib.request.urlopen(request, timeout=30) as response:
        return response.read()


def _remote(args: argparse.Namespace) -> list[dict[str, Any]]:
    base = args.url.rstrip("/")
    query = urllib.parse.urlencode({"ids": ",".join(args.ids)})
    body = json.loads(_get(f"{base}/api/runs/compare?{query}", args.token))
    if args.plot:
        args.plot.write_bytes(_get(base + body["plot"], args.token))
    return body["runs"]


def _local(args: argparse.Namespace) -> list[dict[str, Any]]:
    from app.config import load_settings
    from app.runs import compare

    settings = load_settings()
    folder = args.folder or settings.runs.folder_path
    ids = compare.parse_ids(args.ids)
    unknown = [i for i in ids if not (folder / i / "run.json").is_file()]
    if unknown:
        raise compare.CompareError(f"no run {', '.join(map(repr, unknown))} in {folder}")
    records = [json.loads((folder / i / "run.json").read_text()) for i in ids]
    if args.plot:
        folders = [folder / i for i in ids]
        args.plot.write_bytes(compare.png(records, folders, settings.runs.stats_skip_s))
    return records


def run_compare(args: argparse.Namespace) -> int:
    """Exit 0 with the table; 2 for unknown ids, fewer than two, or a refused request."""
    from app.runs import compare

    try:
        records = _remote(args) if args.url else _local(args)
    except compare.CompareError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except urllib.error.HTTPError as exc:
        try:
            detail = json.load(exc).get("detail")
        except ValueError:
            detail = exc.reason
        print(f"error: {exc.code} {detail}", file=sys.stderr)
        return 2
    if args.json:
        ids = [r["run_id"] for r in records]
        print(json.dumps({"ids": ids, "rows": compare.table(records)}, indent=1))
    else:
        print(compare.format_table(records))
    if args.plot:
        print(f"plot: {args.plot}", file=sys.stderr)
    return 0
