"""Voxelize the VoxGI demo scene (or a .blend) headless and print cascades and timings.

Usage: ``python tools/demo.py [--blend FILE.blend] [--span METRES] [--cascades N]``
(``make demo``, ``make demo BLEND=file.blend``). Without ``--blend`` it builds the demo
scene: a Cornell box, a skinned tube and a rotating sphere. Exit codes: 0 done, 1 the
voxelization reported an error, 2 bad arguments (missing file, not a .blend).
"""
from __future__ import annotations

import argparse
import contextlib
import ctypes
import importlib
import os
import pathlib
import sys
import tempfile
import time

REPO_ROOT = pathlib.Path(__file__).resolve().parent.parent
# Uncompressed, zstd (Blender ≥ 3.0) and gzip (older) .blend headers.
BLEND_MAGICS = (b"BLENDER", b"\x28\xb5\x2f\xfd", b"\x1f\x8b")


def parse_args(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--blend", type=pathlib.Path, help="open this .blend instead of the demo scene")
    parser.add_argument("--span", type=float, help="base voxel span in metres (Scene.voxgi.base_span)")
    parser.add_argument("--cascades", type=int, help="number of cascades (Scene.voxgi.cascade_count)")
    parser.add_argument("--out", type=pathlib.Path, default=REPO_ROOT / "out",
                        help="where preview.exr and the PNG strips go (default: out/)")
    parser.add_argument("--size", type=int, nargs=2, default=(160, 120), metavar=("W", "H"),
                        help="preview size in pixels (default 160 120)")
    parser.add_argument("--cycles-samples", type=int, default=256,
                        help="Cycles samples of the reference strip (0 = no Cycles)")
    return parser.parse_args(argv)


def blend_problem(path: pathlib.Path) -> str | None:
    """Why ``path`` cannot be opened as a .blend, or None."""
    if not path.is_file():
        return f"no such file: {path}"
    with open(path, "rb") as f:
        head = f.read(8)
    if path.suffix.lower() != ".blend" or not head.startswith(BLEND_MAGICS):
        return f"not a .blend file: {path}"
    return None


def import_addon(tmp: str):
    """Register the repository as the add-on package ``voxgi`` (as tests/blender/conftest.py)."""
    (pathlib.Path(tmp) / "voxgi").symlink_to(REPO_ROOT, target_is_directory=True)
    sys.path.insert(0, tmp)
    package = importlib.import_module("voxgi")
    package.register()
    return package


@contextlib.contextmanager
def quiet_stdout():
    """Silence fd 1 (Blender echoes operator reports there); our tables print afterwards."""
    libc = ctypes.CDLL(None)
    sys.stdout.flush()
    saved = os.dup(1)
    with open(os.devnull, "w") as devnull:
        os.dup2(devnull.fileno(), 1)
    try:
        yield
    finally:
        libc.fflush(None)
        os.dup2(saved, 1)
        os.close(saved)


def run(args: argparse.Namespace, tmp: str) -> int:
    import bpy

    import_addon(tmp)
    from voxgi.blender import reports as report
    from voxgi.blender.demo_scene import build_demo_scene
    from voxgi.blender.session import scene_session

    if args.blend is None:
        bpy.ops.wm.read_factory_settings(use_empty=True)
        build_demo_scene(bpy.context.scene)
        source = "demo scene (Cornell box, skinned tube, rotating sphere)"
    else:
        try:
            bpy.ops.wm.open_mainfile(filepath=str(args.blend.resolve()), load_ui=False)
        except RuntimeError as error:
            print(f"demo: cannot open {args.blend}: {error}", file=sys.stderr)
            return 2
        source = str(args.blend)
    scene = bpy.context.scene
    settings = scene.voxgi
    for flag, name, value in (("--span", "base_span", args.span), ("--cascades", "cascade_count", args.cascades)):
        if value is None:
            continue
        prop = settings.bl_rna.properties[name]
        if not prop.hard_min <= value <= prop.hard_max:  # Blender would clamp silently
            print(f"demo: {flag} {value:g} is outside [{prop.hard_min:g}, {prop.hard_max:g}]", file=sys.stderr)
            return 2
        setattr(settings, name, value)

    start = time.perf_counter()
    with quiet_stdout():  # errors are printed below from the session's report
        try:
            status = bpy.ops.voxgi.voxelize()
        except RuntimeError:  # bpy.ops raises when the operator reports an ERROR
            status = {"CANCELLED"}
    total = time.perf_counter() - start
    session = scene_session(scene.name_full)
    summary = session.snapshot_summary or {}
    print(f"\nVoxGI demo — {source}, scene '{scene.name}', frame {scene.frame_current}")
    spans = ("fitted to the view (Auto)" if settings.span_mode == "AUTO"
             else f"base span {settings.base_span:g} m")
    print(f"voxel spans {spans}, {settings.cascade_count} cascades; "
          f"{summary.get('objects', 0)} objects, {summary.get('triangles', 0):,} triangles\n")
    sys.stdout.flush()
    if status != {"FINISHED"} or session.caches is None:
        for level, message in session.last_report:
            print(f"{level}: {message}", file=sys.stderr)
        return 1
    print("\n".join(report.cascade_table(session.caches)), end="\n\n")
    print("\n".join(report.timing_table(session.timings, total)), end="\n\n")
    warnings = [m for level, m in session.last_report if level == "WARNING"]
    print("\n".join(f"warning: {m}" for m in warnings) if warnings else "no warnings, nothing skipped")
    return gi_section(scene, args)


def gi_section(scene, args) -> int:
    """Render the GI preview (and Cycles' reference at the light paths it predicts) and print
    errors and timings."""
    sys.path.insert(0, str(REPO_ROOT / "tools"))
    import gi_compare

    from voxgi.blender.session import scene_session

    if scene.camera is None:
        print("\nno scene camera: GI preview skipped")
        return 0
    width, height = args.size
    print(f"\nGI preview {width}×{height} → {args.out / 'preview.exr'}")
    with quiet_stdout():
        ours, seconds = gi_compare.render_preview(scene, args.out / "preview.exr", width, height)
    gi_compare.write_strip(args.out / "preview_strip.png", ours)
    timings = scene_session(scene.name_full).gi_timings
    print("\n".join(f"  {name:<18} {ms * 1000:8.1f} ms" for name, ms in timings.items()))
    if args.cycles_samples <= 0:
        return 0
    with quiet_stdout():
        cycles, cycles_seconds = gi_compare.render_cycles(scene, width, height, args.cycles_samples,
                                                          scene.voxgi.ao_distance)
    gi_compare.write_strip(args.out / "cycles_strip.png", cycles)
    errors = gi_compare.pass_errors(ours, cycles)
    print(f"\nstrips: {args.out / 'preview_strip.png'} and {args.out / 'cycles_strip.png'} "
          f"({', '.join(gi_compare.STRIP_PASSES)})")
    diffuse, glossy = gi_compare.reference_bounces(scene)
    paths = "one bounce" if diffuse == 1 else f"{diffuse} diffuse / {glossy} glossy bounces"
    print(f"preview {seconds:.2f} s vs Cycles {args.cycles_samples} spp, {paths} "
          f"{cycles_seconds:.2f} s; relative L1 error vs Cycles:")
    print("\n".join(f"  {name:<18} {value:.3f}" for name, value in errors.items()))
    return 0


def main(argv=None) -> int:
    args = parse_args(argv)
    if args.blend is not None and (problem := blend_problem(args.blend)):
        print(f"demo: {problem}", file=sys.stderr)  # checked before the slow `import bpy`
        return 2
    with tempfile.TemporaryDirectory(prefix="voxgi-demo-") as tmp:
        return run(args, tmp)


if __name__ == "__main__":
    sys.exit(main())
