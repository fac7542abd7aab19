"""Makes the gallery's pictures: every arena family filmed with ``jarena render`` on the CPU, kept small.

    python docs/gallery/make_gallery.py                  # all (about 15 minutes on 2 CPU cores)
    python docs/gallery/make_gallery.py classic-pendulum cloth-flattening   # some

Each clip is rendered by the command line (``python -m jarena.cli render ... --format gif``) into a temporary
folder, then cut to a few frames, scaled and reduced to a small palette, and written beside this script. The
pixels picture also shows the walker as the on-device camera (``pixels:64``) sees it. A picture over
``MAX_BYTES`` fails the script: the gallery is committed, and stays a few MB in all.

Brax's arenas have no render function (``jarena render`` refuses them, naming the arenas that render), so the ant
is drawn here from its states: a short random-action rollout of ``brax|env:ant``, its positions set on the MuJoCo
model Brax builds the ant from and drawn by ``mujoco.Renderer``.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import imageio.v3 as iio
import numpy as np
from PIL import Image, ImageDraw

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
MAX_BYTES = 300_000


@dataclasses.dataclass(frozen=True)
class Clip:
    """One ``jarena render`` call and how its frames become the gallery's picture."""

    name: str
    agent: str
    arena: str
    episodes: tuple[int, ...] = (0,)
    size: tuple[int, int] = (160, 120)
    max_steps: int | None = None
    every: int = 1  # keep every n-th frame
    colours: int = 64  # palette size of the GIF
    fps: float = 20.0
    camera: str = "-1"
    still: bool = False  # a PNG of the first and last frames instead of a GIF
    sets: tuple[str, ...] = ()


CLIPS = [
    Clip("classic-cartpole", "oracle_cartpole", "classic|domain:cartpole,task:balance", max_steps=120, every=2),
    Clip("classic-pendulum", "oracle_pendulum", "classic|domain:pendulum,task:swingup", episodes=(42,),
         max_steps=80),
    Clip("classic-acrobot", "random", "classic|domain:acrobot,task:swingup", max_steps=120, every=2),
    Clip("classic-point-mass", "oracle_point_mass", "classic|domain:point_mass,task:reach", episodes=(0, 1, 2, 3),
         size=(80, 80), max_steps=60, every=2),
    Clip("dmc-cartpole", "oracle_dmc_cartpole", "dmc|domain:cartpole,task:swingup", max_steps=300, every=4,
         colours=48, fps=25.0, camera="0"),
    Clip("dmc-walker", "random", "dmc|domain:walker,task:walk", max_steps=80, every=2, colours=48, camera="0"),
    Clip("cloth-flattening", "oracle_cloth_flattening", "cloth|initial:crumpled,particles:24,horizon:8",
         episodes=(0, 1, 2, 3), size=(128, 128), still=True),
]


def render(clip: Clip, folder: Path) -> np.ndarray:
    """The clip's frames (T, H, W, 3), filmed by the command line."""
    out = folder / f"{clip.name}.gif"
    command = [sys.executable, "-m", "jarena.cli", "render", clip.agent, clip.arena, "--out", str(out),
               "--episode", *map(str, clip.episodes), "--width", str(clip.size[0]), "--height", str(clip.size[1]),
               "--camera", clip.camera, "--fps", str(clip.fps)]
    if clip.max_steps is not None:
        command += ["--max-steps", str(clip.max_steps)]
    for item in clip.sets:
        command += ["--set", item]
    print("$", " ".join(repr(c) if " " in c or "|" in c else c for c in command), flush=True)
    subprocess.run(command, check=True, cwd=folder)
    # imageio reads a GIF's frames whole; the writer dropped repeated frames, which is what the gallery wants
    return np.asarray(iio.imread(out, index=None))[..., :3]


def palette_gif(frames: np.ndarray, path: Path, colours: int, fps: float) -> None:
    """A looping GIF with one shared palette of ``colours`` (small files; the scenes have few colours)."""
    strip = Image.fromarray(np.concatenate(list(frames[:: max(1, len(frames) // 8)]), axis=1))
    palette = strip.quantize(colors=colours, method=Image.Quantize.MEDIANCUT)
    images = [Image.fromarray(f).quantize(palette=palette, dither=Image.Dither.NONE) for f in frames]
    images[0].save(path, save_all=True, append_images=images[1:], loop=0, duration=round(1000 / fps),
                   optimize=True, disposal=1)


def labelled(frame: np.ndarray, text: str) -> Image.Image:
    image = Image.fromarray(frame)
    canvas = Image.new("RGB", (image.width, image.height + 18), "white")
    canvas.paste(image, (0, 18))
    ImageDraw.Draw(canvas).text((4, 3), text, fill="black")
    return canvas


def before_after(frames: np.ndarray, path: Path) -> None:
    """The first and the last frame side by side, labelled."""
    before, after = labelled(frames[0], "before"), labelled(frames[-1], "after the oracle")
    canvas = Image.new("RGB", (before.width * 2 + 8, before.height), "white")
    canvas.paste(before, (0, 0))
    canvas.paste(after, (before.width + 8, 0))
    canvas.save(path, optimize=True)


def walker_pixels(folder: Path) -> None:
    """The walker at eval episode 0's start: MuJoCo's renderer on camera 0, and the on-device camera's 64 x 64."""
    string = "dmc|domain:walker,task:walk,pixels:64"
    host = render(Clip("walker-camera0", "random", string, size=(64, 64), max_steps=1, camera="0"), folder)[0]
    code = ("import sys, jax, numpy as np, jarena\n"
            f"arena = jarena.build_arena({string!r})\n"
            "state, info = jax.jit(lambda: arena.reset(episode=0))()\n"
            "np.save(sys.argv[1], np.asarray(info.observation['pixels']))\n")
    target = folder / "device.npy"
    subprocess.run([sys.executable, "-c", code, str(target)], check=True, cwd=folder)
    device = np.load(target)[..., :3]
    scale = lambda image: np.asarray(Image.fromarray(image).resize((128, 128), Image.Resampling.NEAREST))
    left, right = labelled(scale(host), "mujoco.Renderer"), labelled(scale(device), "on device, pixels:64")
    canvas = Image.new("RGB", (left.width * 2 + 8, left.height), "white")
    canvas.paste(left, (0, 0))
    canvas.paste(right, (left.width + 8, 0))
    canvas.save(HERE / "dmc-walker-pixels.png", optimize=True)


BRAX_ANT = """
import sys, jax, jax.numpy as jnp, numpy as np, jarena
arena = jarena.build_arena("brax|env:ant,backend:positional")
state, info = arena.reset(jax.random.key(0), episode=0)
def step(state, key):
    state, info = arena.step(state, arena.sample_action(key))
    return state, state.physics.pipeline_state.q
_, q = jax.jit(lambda s: jax.lax.scan(step, s, jax.random.split(jax.random.key(1), int(sys.argv[2]))))(state)
np.save(sys.argv[1], np.concatenate([np.asarray(state.physics.pipeline_state.q)[None], np.asarray(q)]))
"""


def brax_ant(folder: Path, steps: int = 100, size: tuple[int, int] = (160, 120)) -> None:
    """Random actions on Brax's ant, drawn by MuJoCo's renderer from the rollout's positions."""
    import brax.envs
    import mujoco

    target = folder / "ant.npy"
    subprocess.run([sys.executable, "-c", BRAX_ANT, str(target), str(steps)], check=True, cwd=folder)
    positions = np.load(target)
    model = brax.envs.get_environment("ant", backend="positional").sys.mj_model
    data = mujoco.MjData(model)
    camera = mujoco.MjvCamera()
    camera.distance, camera.elevation, camera.azimuth = 4.0, -25.0, 120.0
    camera.lookat[:] = positions[0, :3]  # fixed: a floor that does not scroll keeps the GIF small
    frames = []
    with mujoco.Renderer(model, height=size[1], width=size[0]) as renderer:
        for q in positions[::2]:
            data.qpos[:] = q
            mujoco.mj_forward(model, data)
            renderer.update_scene(data, camera)
            frames.append(renderer.render().copy())
    palette_gif(np.stack(frames), HERE / "brax-ant.gif", 32, 10.0)


def montage() -> None:
    """One frame of each family in a row: the picture of the README and the home page."""
    picks = [("classic-pendulum.gif", -1), ("classic-cartpole.gif", 10), ("dmc-cartpole.gif", -1),
             ("dmc-walker.gif", 8), ("brax-ant.gif", 20)]
    tiles = []
    for name, index in picks:
        frames = np.asarray(iio.imread(HERE / name, index=None))[..., :3]
        tile = Image.fromarray(frames[min(index, len(frames) - 1) if index >= 0 else -1]).convert("RGB")
        tiles.append(tile.resize((160, 120)))
    cloth = Image.open(HERE / "cloth-flattening.png").convert("RGB")
    half = cloth.crop((cloth.width // 2 + 4, 18, cloth.width, cloth.height))
    tiles.append(half.resize((120, 120)))
    canvas = Image.new("RGB", (sum(t.width for t in tiles) + 4 * (len(tiles) - 1), 120), "white")
    x = 0
    for tile in tiles:
        canvas.paste(tile, (x, 0))
        x += tile.width + 4
    canvas.save(HERE / "montage.png", optimize=True)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    names = [c.name for c in CLIPS] + ["brax-ant", "dmc-walker-pixels", "montage"]
    parser.add_argument("names", nargs="*", metavar="NAME", help=f"pictures to make, of {names} (default: all)")
    args = parser.parse_args()
    unknown = sorted(set(args.names) - set(names))
    if unknown:
        parser.error(f"unknown pictures {unknown}; choose from {names}")
    wanted = set(args.names or names)
    os.environ.setdefault("JAX_PLATFORMS", "cpu")
    os.environ.setdefault("MUJOCO_GL", "egl")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for clip in CLIPS:
            if clip.name not in wanted:
                continue
            start = time.time()
            frames = render(clip, folder)[:: clip.every]
            if clip.still:
                before_after(frames, HERE / f"{clip.name}.png")
            else:
                palette_gif(frames, HERE / f"{clip.name}.gif", clip.colours, clip.fps / clip.every)
            print(f"{clip.name}: {len(frames)} frames in {time.time() - start:.0f} s", flush=True)
        if "brax-ant" in wanted:
            brax_ant(folder)
        if "dmc-walker-pixels" in wanted:
            walker_pixels(folder)
        if "montage" in wanted:
            montage()
    sizes = {p.name: p.stat().st_size for p in sorted(HERE.iterdir()) if p.suffix in (".gif", ".png")}
    for name, size in sizes.items():
        print(f"{name:28s} {size / 1000:7.1f} KB")
    print(f"{'all':28s} {sum(sizes.values()) / 1000:7.1f} KB")
    too_big = [name for name, size in sizes.items() if size > MAX_BYTES]
    if too_big:
        print(f"over {MAX_BYTES} bytes: {too_big}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
