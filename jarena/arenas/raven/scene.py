"""The tabletop scene: Ravens' objects as MuJoCo boxes, a table, and a floating suction cup, as one MJX model.

Each object is a body of box geoms (:class:`Shape`), built from the sizes of Ravens' URDF files. Movable objects
have a free joint; fixed ones (Ravens' ``fixed`` category, e.g. the insertion fixture) are mocap bodies, so that
each episode places them through ``mjx.Data.mocap_pos`` without changing the model. The suction cup is a mocap
body without collisions, and every movable object has a weld equality to it, inactive until the cup grasps
the object (:mod:`.physics`).

Contacts are kept few: by default movable objects collide with the table, the fixed objects and each other
(``contype`` 1, ``conaffinity`` 1); the table and fixed objects (``contype`` 0) never collide among themselves; the
cup collides with nothing (its touch is found by a ray, :mod:`.geometry`). An :class:`Item` may narrow its
collisions further (its ``contype`` and ``conaffinity`` bits), a scene may list explicit contact pairs of objects
(MuJoCo's ``<pair>``: the only ones between objects whose bits rule each other out), and a :class:`Box` that is
not ``solid`` is only seen (by the heightmap and the cup's ray), never touched: a part's look and its collision can
be separate boxes.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import mujoco

TABLE_RGB = (0.2, 0.2, 0.2)
"""The table's colour: Ravens' workspace plane (dark grey)."""
CUP_HEIGHT = 0.029
"""The suction head's length, metres (Ravens' suction head, tip to mount)."""

COLORS = {
    "blue": (78.0, 121.0, 167.0), "red": (255.0, 87.0, 89.0), "green": (89.0, 169.0, 79.0),
    "orange": (242.0, 142.0, 43.0), "yellow": (237.0, 201.0, 72.0), "purple": (176.0, 122.0, 161.0),
    "pink": (255.0, 157.0, 167.0), "cyan": (118.0, 183.0, 178.0), "brown": (156.0, 117.0, 95.0),
    "gray": (186.0, 176.0, 172.0),
}
"""Ravens' palette (``utils.COLORS``), 0-255."""


def rgb(name: str) -> tuple[float, float, float]:
    """A colour of :data:`COLORS` in [0, 1]."""
    return tuple(c / 255.0 for c in COLORS[name])


@dataclasses.dataclass(frozen=True)
class Box:
    """A box part of a shape.

    Attributes:
      size: full extents (x, y, z), metres.
      pos: its centre in the body frame, metres.
      yaw: its heading in the body frame, radians.
      solid: whether it collides (``False``: seen, never touched).
      rgb: its colour in [0, 1] (``None``: the object's).
    """

    size: tuple[float, float, float]
    pos: tuple[float, float, float] = (0.0, 0.0, 0.0)
    yaw: float = 0.0
    solid: bool = True
    rgb: tuple[float, float, float] | None = None


@dataclasses.dataclass(frozen=True)
class Shape:
    """An object kind.

    Attributes:
      name: a short name (``ell``).
      boxes: the box parts, in the body frame (the body's origin is at half its height, as Ravens' URDFs).
      extent: Ravens' ``size`` of the object for placing it (x, y, z), metres: the layout keeps a square of side
        ``hypot(x, y)`` around it free of other objects, and its origin stands ``z / 2`` above the table.
      mass: kilograms (movable shapes).
      friction: sliding friction coefficient (Ravens' ``lateral_friction``).
      fixed: whether the object is part of the scenery (Ravens' ``fixed`` objects): it never moves.
      rgb: default colour in [0, 1].
      resizable: whether a task sets its boxes' sizes and positions per episode (``boxes`` then give the largest;
        :attr:`.physics.RavenPhysics.geom_size`).
    """

    name: str
    boxes: tuple[Box, ...]
    extent: tuple[float, float, float]
    mass: float = 0.1
    friction: float = 1.0
    fixed: bool = False
    rgb: tuple[float, float, float] = rgb("red")
    resizable: bool = False


ELL = Shape("ell", (Box((0.08, 0.03, 0.04), (0.025, 0.0, 0.0)), Box((0.03, 0.08, 0.0399), (0.0, 0.025, 0.0))),
            extent=(0.1, 0.1, 0.04), mass=0.1, friction=0.3, rgb=(1.0, 0.3412, 0.3490))
"""Ravens' ``insertion/ell.urdf``: an L of two 3 cm wide arms, 8 cm long and 4 cm high, its origin at their corner."""

FIXTURE = Shape("fixture", (
    Box((0.1, 0.002, 0.04), (0.025, -0.025, 0.0)), Box((0.05, 0.002, 0.04), (0.0, 0.075, 0.0)),
    Box((0.05, 0.002, 0.04), (0.05, 0.025, 0.0)), Box((0.002, 0.105, 0.04), (-0.025, 0.025, 0.0)),
    Box((0.002, 0.055, 0.04), (0.025, 0.05, 0.0)), Box((0.002, 0.055, 0.04), (0.075, 0.0, 0.0))),
    extent=(0.1, 0.1, 0.04), fixed=True, friction=0.3, rgb=(0.7294, 0.6902, 0.6745))
"""Ravens' ``insertion/fixture.urdf``: 2 mm walls, 4 cm high, around an L channel 4.8 cm wide that holds
:data:`ELL` with 9 mm to spare on each side (its 1 mm pad under the corner is left out)."""

BLOCK = Shape("block", (Box((0.04, 0.04, 0.04)),), extent=(0.04, 0.04, 0.04), mass=0.01, friction=1.0)
"""Ravens' ``stacking/block.urdf``: a 4 cm cube."""


def octagon(inradius: float, height: float, z: float, solid: tuple[bool, bool] = (False, False),
            rgb: tuple[float, float, float] | None = None) -> tuple[Box, ...]:
    """A regular octagon prism of ``inradius`` (metres, centre to side), ``height`` (metres), centred ``z`` above the
    origin, as the union of four boxes (arms at 0, 45, 90 and 135 degrees); ``solid``: whether the arms at 0 and
    90 degrees collide (the others never do)."""
    length, width = 2 * inradius, 2 * inradius * np.tan(np.pi / 8)
    return tuple(Box((length, width, height), (0.0, 0.0, z), yaw=k * np.pi / 4,
                     solid=solid[k // 2] if k % 2 == 0 else False, rgb=rgb) for k in range(4))


def _octagon_wall(inradius: float, thickness: float, height: float) -> tuple[Box, ...]:
    """Eight upright walls (seen, never touched) around an octagon of outer ``inradius``, standing on the origin."""
    length = 2 * inradius * np.tan(np.pi / 8)
    middle = inradius - thickness / 2
    return tuple(Box((thickness, length, height), (middle * np.cos(a), middle * np.sin(a), height / 2), yaw=a,
                     solid=False) for a in np.arange(8) * np.pi / 4)


_BOWL_LOOK = _octagon_wall(0.058, 0.006, 0.035) + octagon(0.052, 0.005, 0.0025)
BOWL = Shape("bowl", (Box((0.07, 0.07, 0.005), (0.0, 0.0, 0.0025)),) + _BOWL_LOOK, extent=(0.12, 0.12, 0.0),
             mass=0.1, friction=1.0, rgb=rgb("green"))
"""Ravens' ``bowl/bowl.urdf`` (a 11.6 x 11.8 x 3.5 cm cup mesh, centred here on its origin): an octagonal bowl 11.6
cm across and 3.5 cm high, its origin on the table. Its walls and floor are only seen; a 7 cm square under the
floor, 5 mm thick, is what touches (the table, and blocks put in the bowl)."""
BOWL_FIXED = dataclasses.replace(BOWL, boxes=_BOWL_LOOK, fixed=True)
""":data:`BOWL` as scenery (place-red-in-green's target bowls): seen, never touched; blocks put in it rest on the
table, inside its 5 mm floor."""

_LIGHT, _MIDDLE, _DARK = (0.9176, 0.6882, 0.5588), (0.6118, 0.4588, 0.3725), (0.3059, 0.2294, 0.1863)
PYRAMID_BASE = Shape("stand", (Box((0.05, 0.15, 0.005), rgb=_MIDDLE),) + tuple(
    Box((0.05, 0.05, 0.005), (0.0, y, 0.0), solid=False, rgb=c)
    for y, c in ((0.0, _MIDDLE), (-0.05, _LIGHT), (0.05, _DARK))),
    extent=(0.05, 0.15, 0.005), fixed=True, friction=1.0, rgb=_MIDDLE)
"""Ravens' ``stacking/stand.urdf``: three 5 x 5 x 0.5 cm squares in a row, in three browns (one slab touches)."""

HANOI_STAND = Shape("stand", (Box((0.12, 0.36, 0.01), rgb=_MIDDLE),) + tuple(
    Box((0.12, 0.12, 0.01), (0.0, y, 0.0), solid=False, rgb=c)
    for y, c in ((0.0, _MIDDLE), (-0.12, _LIGHT), (0.12, _DARK))) + tuple(
    Box((0.01, 0.01, 0.05), (0.0, y, 0.03), solid=False, rgb=_MIDDLE) for y in (-0.12, 0.0, 0.12)),
    extent=(0.12, 0.36, 0.01), fixed=True, friction=0.5, rgb=_MIDDLE)
"""Ravens' ``hanoi/stand.urdf``: three 12 x 12 x 1 cm slabs in a row, each with a rod 5 cm high (1 cm square here,
1 cm across in Ravens) at its centre. The rods are only seen: a disk goes down over one without touching it."""


def disk(index: int) -> Shape:
    """Ravens' ``hanoi/disk{index}.urdf``: a ring 1 cm thick, 6, 7 or 8 cm across (a 3 cm hole), here a solid
    octagon (the rod shows through it from above); red, yellow, green."""
    radius = (0.03, 0.035, 0.04)[index]
    colour = ((1.0, 0.3412, 0.349), (0.9294, 0.7882, 0.2824), (0.349, 0.6627, 0.3098))[index]
    return Shape(f"disk{index}", octagon(radius, 0.01, 0.0, solid=(True, True)),
                 extent=(2 * radius, 2 * radius, 0.01), mass=0.1, friction=1.0, rgb=colour)


CORNER = Shape("corner", (Box((0.055, 0.005, 0.001), (0.0525, 0.0775, 0.0), solid=False),
                          Box((0.005, 0.055, 0.001), (0.0775, 0.0525, 0.0), solid=False)),
               extent=(0.15, 0.15, 0.0), fixed=True, friction=0.3, rgb=(0.0, 1.0, 0.0), resizable=True)
"""Ravens' ``corner/corner-template.urdf``: two green marks 5.5 cm long, 5 mm wide and 1 mm high, in an L around
a box's +x +y corner (their positions follow the episode's box). Only seen, as in Ravens."""

BOX = Shape("box", (Box((0.15, 0.15, 0.06)),), extent=(0.15, 0.15, 0.06), mass=0.1, friction=1.0,
            rgb=rgb("brown"), resizable=True)
"""Ravens' ``box/box-template.urdf``: a box of the episode's size (at most 15 x 15 x 6 cm), 0.1 kg."""


def box(size: tuple[float, float, float]) -> Shape:
    """Ravens' ``box/box-template.urdf`` filled with a fixed ``size`` (full extents, metres): 0.1 kg, brown."""
    return Shape("box", (Box(tuple(float(s) for s in size)),), extent=tuple(float(s) for s in size), mass=0.1,
                 friction=1.0, rgb=rgb("brown"))


PALLET = Shape("pallet", (Box((0.3, 0.25, 0.0375)),), extent=(0.3, 0.25, 0.0375), fixed=True, friction=1.0,
               rgb=(0.8706, 0.7216, 0.5294))
"""Ravens' ``pallet/pallet.urdf`` (a mesh of slats, 0.3 x 0.25 x 0.0375 m about its origin): a solid slab of its
size, light wood."""



@dataclasses.dataclass(frozen=True)
class Item:
    """One object of a scene: its ``name`` (unique), ``shape`` and colour (``None``: the shape's), and the
    collision bits of its solid boxes (MuJoCo's ``contype`` and ``conaffinity``; ``None``: 1 and 1 for movable
    objects, 0 and 1 for fixed ones). Two boxes touch when either's ``contype`` shares a bit with the other's
    ``conaffinity``; the table has ``contype`` 0 and ``conaffinity`` 1."""

    name: str
    shape: Shape
    rgb: tuple[float, float, float] | None = None
    contype: int | None = None
    conaffinity: int | None = None

    @property
    def collision(self) -> tuple[int, int]:
        """``(contype, conaffinity)`` of the item's solid boxes."""
        default = (0, 1) if self.shape.fixed else (1, 1)
        return (default[0] if self.contype is None else self.contype,
                default[1] if self.conaffinity is None else self.conaffinity)

    @property
    def colour(self) -> tuple[float, float, float]:
        return self.shape.rgb if self.rgb is None else self.rgb


@dataclasses.dataclass(frozen=True)
class PhysicsOptions:
    """Simulation settings (static: they shape the compiled program).

    Attributes:
      timestep: seconds per physics step.
      iterations, ls_iterations: the constraint solver's (Newton) iterations and line-search iterations.
      max_geom_pairs: ``None``, or at most this many pairs of boxes (of those their collision bits and the
        explicit pairs allow) go through collision detection at each physics step: the nearest, by the distance
        between their bounding spheres (MJX's broad phase, its ``max_geom_pairs``); the table's pairs are all
        kept.
    """

    timestep: float = 0.005
    iterations: int = 10
    ls_iterations: int = 10
    max_geom_pairs: int | None = None


def _box_geom(box: Box, colour, collision: tuple[int, int], mass: float | None, friction: float,
              name: str | None = None) -> str:
    half = " ".join(f"{s / 2:.6g}" for s in box.size)
    pos = " ".join(f"{p:.6g}" for p in box.pos)
    quat = f"{np.cos(box.yaw / 2):.9g} 0 0 {np.sin(box.yaw / 2):.9g}"
    colour = colour if box.rgb is None else box.rgb
    contype, conaffinity = collision if box.solid else (0, 0)
    mass_attr = f' mass="{mass:.6g}"' if mass is not None else ""
    name_attr = f'name="{name}" ' if name is not None else ""
    return (f'<geom {name_attr}type="box" size="{half}" pos="{pos}" quat="{quat}" '
            f'rgba="{colour[0]:.4g} {colour[1]:.4g} {colour[2]:.4g} 1" contype="{contype}" '
            f'conaffinity="{conaffinity}" friction="{friction:.4g} 0.005 0.0001"{mass_attr}/>')


def _geom_name(item: Item, k: int) -> str:
    return f"{item.name}_box{k}"


def mjcf(items: tuple[Item, ...], options: PhysicsOptions, pairs: tuple[tuple[str, str], ...] = ()) -> str:
    """The MJCF of a scene with ``items`` (movable ones first in the model's body order) and explicit contact
    ``pairs`` of items (each solid box of one with each of the other, whatever their collision bits)."""
    paired = {name for pair in pairs for name in pair}
    bodies, welds = [], []
    for i, item in enumerate(items):
        shape = item.shape
        names = [_geom_name(item, k) if item.name in paired else None for k in range(len(shape.boxes))]
        # park every object apart, off the table's workspace, until an episode places it
        parked = f"{2.0 + 0.3 * i:.3f} 2.0 {shape.extent[2] / 2:.4f}"
        if shape.fixed:
            geoms = "".join(_box_geom(b, item.colour, item.collision, None, shape.friction, n)
                            for b, n in zip(shape.boxes, names, strict=True))
            bodies.append(f'<body name="{item.name}" mocap="true" pos="{parked}">{geoms}</body>')
        else:
            volume = [float(np.prod(b.size)) for b in shape.boxes]
            geoms = "".join(_box_geom(b, item.colour, item.collision, shape.mass * v / sum(volume), shape.friction,
                                      n) for b, v, n in zip(shape.boxes, volume, names, strict=True))
            bodies.append(f'<body name="{item.name}" pos="{parked}"><freejoint name="{item.name}"/>{geoms}</body>')
            welds.append(f'<weld name="grasp_{item.name}" body1="cup" body2="{item.name}" active="false"/>')
    table = " ".join(f"{c:.4g}" for c in TABLE_RGB)
    by_name = {item.name: item for item in items}
    contacts = "".join(
        f'<pair geom1="{_geom_name(by_name[a], j)}" geom2="{_geom_name(by_name[b], k)}"/>'
        for a, b in pairs for j, box_a in enumerate(by_name[a].shape.boxes) if box_a.solid
        for k, box_b in enumerate(by_name[b].shape.boxes) if box_b.solid)
    contact = f"\n  <contact>{contacts}</contact>" if pairs else ""
    if options.max_geom_pairs is not None:
        contact += f'\n  <custom><numeric name="max_geom_pairs" data="{int(options.max_geom_pairs)}"/></custom>'
    return f"""<mujoco model="raven">
  <option timestep="{options.timestep}" iterations="{options.iterations}" ls_iterations="{options.ls_iterations}"
          cone="pyramidal"/>
  <worldbody>
    <geom name="table" type="plane" size="0 0 1" rgba="{table} 1" contype="0" conaffinity="1"
          friction="1 0.005 0.0001"/>
    {"".join(bodies)}
    <body name="cup" mocap="true" pos="0.5 0 0.5">
      <geom type="cylinder" size="0.01 {CUP_HEIGHT / 2}" pos="0 0 {CUP_HEIGHT / 2}" rgba="0.18 0.51 0.77 1"
            contype="0" conaffinity="0" mass="0.1"/>
    </body>
  </worldbody>
  <equality>{"".join(welds)}</equality>{contact}
</mujoco>"""


@dataclasses.dataclass(frozen=True, eq=False)
class Scene:
    """A scene's model and the indices that tie its objects to the model (static numpy arrays).

    Objects are numbered in ``items`` order. The drawable geoms (every box, not the cup) are listed with the
    object each belongs to; the table is the plane ``z = 0``, object ``-1``.

    Attributes:
      items: the objects.
      model: the MuJoCo model.
      movable: int (M,): the objects with a free joint, in ``items`` order; weld ``k`` grasps ``movable[k]``.
      qpos_address: int (M,): where each movable object's 7 free-joint coordinates start in ``qpos``.
      qvel_address: int (M,): where its 6 velocities start in ``qvel``.
      mocap: int (N,): each object's mocap index, -1 for movable objects.
      cup: the cup's mocap index.
      geom: int (G,): the drawable box geoms' ids; ``geom_object`` int (G,) their object; ``geom_size`` float32
        (G, 3) half extents; ``geom_pos`` float32 (G, 3) centres in their body's frame; ``geom_quat`` float32
        (G, 4) orientations in their body's frame; ``geom_rgb`` float32 (G, 3) colours in [0, 1]; ``geom_solid``
        bool (G,) whether each collides. Sizes, positions, orientations and colours are the model's; a task may
        change them per episode (:class:`.physics.RavenPhysics`).
      movable_slot: int (N,): each object's index in ``movable``, -1 for fixed objects.
      resizable: whether a task changes boxes' sizes or positions per episode (any :attr:`Shape.resizable`).
    """

    items: tuple[Item, ...]
    model: mujoco.MjModel
    movable: np.ndarray
    qpos_address: np.ndarray
    qvel_address: np.ndarray
    mocap: np.ndarray
    cup: int
    geom: np.ndarray
    geom_object: np.ndarray
    geom_size: np.ndarray
    geom_pos: np.ndarray
    geom_quat: np.ndarray
    geom_rgb: np.ndarray
    geom_solid: np.ndarray
    movable_slot: np.ndarray
    resizable: bool = False

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(item.name for item in self.items)

    def index(self, name: str) -> int:
        """The object named ``name``; a ``KeyError`` listing the scene's objects otherwise."""
        if name not in self.names:
            raise KeyError(f"the scene has no object {name!r}; it has {list(self.names)}")
        return self.names.index(name)


def build_scene(items: tuple[Item, ...], options: PhysicsOptions = PhysicsOptions(),
                pairs: tuple[tuple[str, str], ...] = ()) -> Scene:
    """The :class:`Scene` of ``items`` (movable objects first), its model compiled from :func:`mjcf` with the
    explicit contact ``pairs`` (names of items)."""
    names = [item.name for item in items]
    if len(set(names)) != len(names):
        raise ValueError(f"object names must be unique, got {names}")
    unknown = sorted({n for pair in pairs for n in pair} - set(names))
    if unknown:
        raise ValueError(f"contact pairs name objects {unknown} that the scene does not have; it has {names}")
    kinds = [item.shape.fixed for item in items]
    if kinds != sorted(kinds):
        raise ValueError(f"list the movable objects before the fixed ones, got {names}")
    import mujoco  # imported when a scene is built, so that importing jarena does not load MuJoCo

    model = mujoco.MjModel.from_xml_string(mjcf(tuple(items), options, tuple(pairs)))
    body = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, n) for n in names]
    movable = np.array([i for i, item in enumerate(items) if not item.shape.fixed], np.int32)
    joints = [model.body_jntadr[body[i]] for i in movable]
    object_of_body = {b: i for i, b in enumerate(body)}
    geoms = [g for g in range(model.ngeom) if model.geom_bodyid[g] in object_of_body]
    slot = np.full(len(items), -1, np.int32)
    slot[movable] = np.arange(movable.size, dtype=np.int32)
    return Scene(
        items=tuple(items), model=model, movable=movable,
        qpos_address=np.array([model.jnt_qposadr[j] for j in joints], np.int32),
        qvel_address=np.array([model.jnt_dofadr[j] for j in joints], np.int32),
        mocap=np.array([model.body_mocapid[b] for b in body], np.int32),
        cup=int(model.body_mocapid[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "cup")]),
        geom=np.array(geoms, np.int32),
        geom_object=np.array([object_of_body[model.geom_bodyid[g]] for g in geoms], np.int32),
        geom_size=np.asarray(model.geom_size[geoms], np.float32).reshape(-1, 3),
        geom_pos=np.asarray(model.geom_pos[geoms], np.float32).reshape(-1, 3),
        geom_quat=np.asarray(model.geom_quat[geoms], np.float32).reshape(-1, 4),
        geom_rgb=np.asarray(model.geom_rgba[geoms, :3], np.float32).reshape(-1, 3),
        geom_solid=np.asarray((model.geom_contype[geoms] | model.geom_conaffinity[geoms]) > 0).reshape(-1),
        movable_slot=slot, resizable=any(item.shape.resizable for item in items))
