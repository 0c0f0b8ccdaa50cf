"""``fidelity info``: what this installation can do (for bug reports and CI logs)."""

from __future__ import annotations

import click

from fidelity.cli.context import write_json_output
from fidelity.cli.options import common_options, json_option
from fidelity.core.fileio import check_outputs
from fidelity.pipeline.environment import describe_environment


@click.command()
@click.option("--probe/--no-probe", default=True, show_default=True,
              help="Probe which Mitsuba variant renders here (a few seconds).")
@json_option("Also write it as JSON")
@common_options
def info(probe: bool, json_path: str | None) -> None:
    """Versions, Mitsuba variant, ONNX providers, chart detection, shared data found."""
    check_outputs({"--json": json_path})
    env = describe_environment(probe=probe)
    click.echo(f"fidelity {env['fidelity']}, Python {env['python']}, {env['platform']}, "
               f"{env['cpus']} CPU(s)")
    deps = env["dependencies"]
    click.echo("dependencies: " + ", ".join(f"{k} {v or 'MISSING'}" for k, v in deps.items()))
    for extra, pkgs in env["extras"].items():
        state = "installed" if all(pkgs.values()) else "not installed"
        click.echo(f"extra [{extra}] {state}: " + ", ".join(f"{k} {v or 'missing'}"
                                                         for k, v in pkgs.items()))
    m = env["mitsuba"]
    if not m["probed"]:
        click.echo("mitsuba: not probed (--probe)")
    elif m.get("variant"):
        lib = f" with libLLVM {m['libllvm']}" if m.get("libllvm") else ""
        click.echo(f"mitsuba: renders with {m['variant']}{lib}")
    else:
        click.echo(f"mitsuba: unavailable ({m.get('error')}); the closed form renders")
    o = env["onnxruntime"]
    click.echo(f"onnxruntime: providers {', '.join(o.get('available', []))}; detectors use "
               f"{', '.join(o.get('used', []))}")
    click.echo(f"COCO scorer (auto): {env['coco_scorer']}")
    c = env["chart_detection"]
    click.echo("chart detection: " + (f"usable (OpenCV {c['opencv']})" if c["usable"] else
                                      f"unusable, give --corners ({c['error']})"))
    s = env["shared"]
    if s["folder"] is None:
        click.echo(f"shared data: not found (looked in {s['looked_in']}); COCO commands need "
                   "paths, the shared-data tests are skipped")
    else:
        click.echo(f"shared data: {s['folder']}: {len(s['models'])} ONNX models "
                   f"({', '.join(s['models'])}), {s['coco_images']} COCO images, annotations "
                   f"{', '.join(s['coco_annotations']) or 'none'}")
    t = env["prediction_tables"]
    click.echo(f"prediction tables: {', '.join(t['available'])} (default {t['default']})")
    if json_path is not None:
        click.echo(f"wrote {write_json_output(json_path, env)}")
