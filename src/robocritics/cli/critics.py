"""``robocritics critics``: the installed critics and the plugins that failed to load."""

from __future__ import annotations

import argparse
import json

from ._common import subcommand


@subcommand("critics")
def _build_critics(sub) -> None:
    p = sub.add_parser(
        "critics",
        help="list the installed critics and the plugins that failed to load",
        description="List every installed critic (built-in and plugins): name, providing package, description.",
    )
    p.add_argument("-v", "--verbose", action="store_true", help="also list each critic's parameters and defaults")
    p.add_argument("--json", action="store_true", help="print the list as JSON")
    p.set_defaults(func=_cmd_critics)


def _cmd_critics(args: argparse.Namespace) -> int:
    from ..critic.plugins import critic_distributions, get_critics, plugin_errors

    critics = get_critics()
    dists = critic_distributions()
    rows = []
    for name, critic in critics.items():
        dist, version = dists.get(name, ("", ""))
        fields = {
            field: {"default": info.default, "description": info.description or ""}
            for field, info in critic.Params.model_fields.items()
        }
        rows.append(
            {"name": name, "package": dist, "version": version, "description": critic.description, "params": fields}
        )
    failed = [
        {"name": e.name, "entry_point": e.value, "package": e.distribution, "error": e.error} for e in plugin_errors
    ]
    if args.json:
        print(json.dumps({"critics": rows, "failed_plugins": failed}, indent=2, default=str))
        return 0
    name_w = max([len(r["name"]) for r in rows] + [4])
    pkg_w = max([len(f"{r['package']} {r['version']}".strip()) for r in rows] + [7])
    print(f"{'NAME':<{name_w}}  {'PACKAGE':<{pkg_w}}  DESCRIPTION")
    for r in rows:
        pkg = f"{r['package']} {r['version']}".strip() or "(registered in-process)"
        print(f"{r['name']:<{name_w}}  {pkg:<{pkg_w}}  {r['description']}")
        if args.verbose:
            for field, info in r["params"].items():
                print(f"{'':<{name_w}}    {field} = {info['default']!r}: {info['description']}")
    if failed:
        print()
        print("Failed plugins (skipped):")
        for f in failed:
            where = f" from {f['package']}" if f["package"] else ""
            print(f"  {f['name']}{where}: {f['error']}")
    return 0
