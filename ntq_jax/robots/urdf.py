"""A serial arm's kinematics and collision spheres, read from a URDF (and an optional SRDF).

:func:`read_arm` turns the files into plain Python numbers (:class:`ArmModel`);
:class:`ntq_jax.robots.serial_arm.SerialArm` is built from them. The parser is
strict: anything it cannot represent exactly is refused with one ``ValueError``
line naming the file, the element and the fix, never silently dropped.

The model:

* The **chain** runs from the root link (the one link that is no joint's child)
  to ``tip`` (a link name), or, without ``tip``, to the child link of the last
  movable joint of the longest chain of movable joints (ties are refused: name
  the tip). Its movable joints (``revolute``, ``continuous``, ``prismatic``) are
  the arm's coordinates, in chain order; ``fixed`` joints are folded into the
  transform before the next movable joint (or into the tip transform).
* **Frames**: frame 0 is the root link's frame (the world frame); frame ``k`` is
  the child link frame of movable joint ``k`` (1-based). ``origin[k]`` is the
  fixed transform from frame ``k - 1`` to joint ``k``'s frame (the joint's
  ``<origin>`` and the fixed joints before it); the joint then rotates about (or
  slides along) its unit ``axis``, given in its own frame:
  ``T_k = T_{k-1} origin[k] motion_k(q_k)``. Transforms are ``(R, t)``, ``R`` a
  row-major 3x3 rotation (9 floats), ``t`` 3 floats; ``<origin rpy>`` is
  ``Rz(yaw) Ry(pitch) Rx(roll)``, as the URDF specifies.
* **Limits**: ``revolute`` and ``prismatic`` joints need ``<limit lower upper>``
  with ``lower < upper``; ``continuous`` joints get ``[-pi, pi]`` (no wrap-around).
* **Spheres**: every ``<collision>`` with ``<geometry><sphere radius>`` of a link
  rigidly attached (through fixed joints) to a chain frame, its centre (the
  collision ``<origin xyz>``; ``rpy`` does not matter for a sphere) expressed in
  that frame. Links beyond the tip through fixed joints (a hand, its fingers)
  belong to the tip's frame. Links whose collision geometry is only meshes (or
  who have none) simply have no spheres; boxes, cylinders and capsules, meshes
  mixed with spheres, and spheres on links that move through a joint off the
  chain are refused.
* **Self-collision**: link pairs are checked unless disabled: the SRDF's
  ``<disable_collisions link1 link2>``, links joined by a joint (adjacent), and
  links rigidly attached to the same frame (their distance never changes).
  Spheres are listed by frame (then in file order), so each link's spheres are
  contiguous, and ``self_blocks`` gives the checked sphere pairs as rectangles of
  sphere index ranges ``(i0, i1, k0, k1)``, ``i1 <= k0``: every sphere of ``i0:i1``
  against every sphere of ``k0:k1``, each range on one frame (the checked link pairs,
  merged where that holds: :func:`merge_blocks`; fewer, larger blocks are faster).
"""

from __future__ import annotations

import dataclasses
import math
import xml.etree.ElementTree as ET
from pathlib import Path

MOVABLE = ("revolute", "continuous", "prismatic")
JOINT_TYPES = MOVABLE + ("fixed",)
SNAP = 1e-9  # transform entries this close to 0 or +-1 are set to it (see _snap)

Transform = tuple[tuple[float, ...], tuple[float, float, float]]  # (R row-major (9,), t (3,))
IDENTITY: Transform = ((1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0), (0.0, 0.0, 0.0))


@dataclasses.dataclass(frozen=True)
class Joint:
    """One movable joint of the chain (see the module docstring for the frames)."""

    name: str
    kind: str  # "revolute", "continuous" or "prismatic"
    origin: Transform  # frame k-1 -> the joint's frame (fixed joints before it folded in)
    axis: tuple[float, float, float]  # unit vector in the joint's frame
    lower: float
    upper: float


@dataclasses.dataclass(frozen=True)
class ArmModel:
    """A serial arm in plain numbers: what :func:`read_arm` returns."""

    name: str
    root: str
    tip: str
    joints: tuple[Joint, ...]
    tip_transform: Transform  # frame n -> the tip link's frame
    sphere_frames: tuple[int, ...]  # (S,) frame of each sphere, 0..n, non-decreasing
    sphere_centers: tuple[tuple[float, float, float], ...]  # (S, 3) in its frame
    sphere_radii: tuple[float, ...]  # (S,)
    sphere_links: tuple[str, ...]  # (S,) the link of each sphere (a link's are contiguous)
    self_blocks: tuple[tuple[int, int, int, int], ...]  # checked sphere pairs, see above
    disabled_links: tuple[tuple[str, str], ...]  # sorted link pairs never checked


def read_arm(urdf_path, srdf_path=None, tip: str | None = None) -> ArmModel:
    """Reads the chain from the root link to ``tip`` of ``urdf_path`` (see the module docstring).

    Raises:
        ValueError: one line naming the file, the element and the fix.
    """
    return _Reader(Path(urdf_path)).read(None if srdf_path is None else Path(srdf_path), tip)


def _snap(v: float) -> float:
    """``v`` with values within :data:`SNAP` of 0, 1 or -1 set to them: ``rpy="1.57079632679 ..."``
    then gives exact zeros, which :mod:`~ntq_jax.robots.serial_arm` skips at trace time (the
    change is far below float32 rounding)."""
    for target in (0.0, 1.0, -1.0):
        if abs(v - target) < SNAP:
            return target
    return v


def rpy_matrix(roll: float, pitch: float, yaw: float) -> tuple[float, ...]:
    """``Rz(yaw) Ry(pitch) Rx(roll)``, row-major (9,)."""
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return (
        cy * cp,
        cy * sp * sr - sy * cr,
        cy * sp * cr + sy * sr,
        sy * cp,
        sy * sp * sr + cy * cr,
        sy * sp * cr - cy * sr,
        -sp,
        cp * sr,
        cp * cr,
    )


def compose(a: Transform, b: Transform) -> Transform:
    """``a b`` (apply ``b``, then ``a``)."""
    ra, ta = a
    rb, tb = b
    r = tuple(
        sum(ra[3 * i + m] * rb[3 * m + j] for m in range(3)) for i in range(3) for j in range(3)
    )
    t = tuple(sum(ra[3 * i + m] * tb[m] for m in range(3)) + ta[i] for i in range(3))
    return r, t


def apply(tf: Transform, p) -> tuple[float, float, float]:
    """``R p + t``."""
    r, t = tf
    return tuple(sum(r[3 * i + m] * p[m] for m in range(3)) + t[i] for i in range(3))


def _snapped(tf: Transform) -> Transform:
    return tuple(_snap(v) for v in tf[0]), tuple(_snap(v) for v in tf[1])


class _Reader:
    """The URDF's links and joints, and the checks, each error naming ``self.path``."""

    def __init__(self, path: Path):
        self.path = path
        self.root_el = self._parse(path, "robot")
        self.links: dict[str, ET.Element] = {}
        for el in self.root_el.findall("link"):
            name = self._attr(el, "name", "<link>")
            if name in self.links:
                self._fail(f"<link name='{name}'> appears twice", "give each link a unique name")
            self.links[name] = el
        if not self.links:
            self._fail("<robot> has no <link>", "a URDF needs at least one link")
        self.joints: dict[str, dict] = {}
        self.parent_joint: dict[str, dict] = {}
        self.children: dict[str, list[dict]] = {name: [] for name in self.links}
        for el in self.root_el.findall("joint"):
            j = self._joint(el)
            if j["name"] in self.joints:
                self._fail(
                    f"<joint name='{j['name']}'> appears twice", "give each joint a unique name"
                )
            if j["child"] in self.parent_joint:
                self._fail(
                    f"link '{j['child']}' is the child of joints "
                    f"'{self.parent_joint[j['child']]['name']}' and '{j['name']}'",
                    "a serial arm's links form a tree: give each link one parent joint",
                )
            self.joints[j["name"]] = j
            self.parent_joint[j["child"]] = j
            self.children[j["parent"]].append(j)

    # ------------------------------------------------------------------ errors and attributes

    def _fail(self, what: str, fix: str, path: Path | None = None):
        raise ValueError(f"{path or self.path}: {what}; fix: {fix}")

    def _parse(self, path: Path, root_tag: str) -> ET.Element:
        try:
            root = ET.parse(path).getroot()
        except FileNotFoundError:
            self._fail("no such file", "give the path of an existing file", path)
        except ET.ParseError as e:
            self._fail(f"not well-formed XML ({e})", "repair the XML", path)
        except OSError as e:
            self._fail(f"cannot be read ({e.strerror})", "give a readable file", path)
        if root.tag != root_tag:
            self._fail(
                f"the root element is <{root.tag}>",
                f"give a URDF / SRDF file (its root element is <{root_tag}>)",
                path,
            )
        return root

    def _attr(self, el: ET.Element, key: str, where: str) -> str:
        value = el.get(key)
        if value is None or not value.strip():
            self._fail(f"{where} has no {key}=", f"give the {key} attribute")
        return value.strip()

    def _numbers(self, text: str | None, count: int, where: str, default=None) -> tuple:
        if text is None:
            if default is None:
                self._fail(f"{where} is missing", f"give {count} numbers")
            return default
        try:
            values = tuple(float(v) for v in text.split())
        except ValueError:
            values = ()
        if len(values) != count or not all(math.isfinite(v) for v in values):
            self._fail(f"{where} is {text!r}", f"give {count} finite numbers separated by spaces")
        return values

    def _number(self, el: ET.Element, key: str, where: str) -> float:
        return self._numbers(self._attr(el, key, where), 1, f"{where} {key}=")[0]

    def _origin(self, el: ET.Element, where: str) -> Transform:
        o = el.find("origin")
        if o is None:
            return IDENTITY
        xyz = self._numbers(o.get("xyz"), 3, f"{where} <origin xyz=>", (0.0, 0.0, 0.0))
        rpy = self._numbers(o.get("rpy"), 3, f"{where} <origin rpy=>", (0.0, 0.0, 0.0))
        return rpy_matrix(*rpy), xyz

    # ------------------------------------------------------------------ joints

    def _joint(self, el: ET.Element) -> dict:
        name = self._attr(el, "name", "<joint>")
        where = f"<joint name='{name}'>"
        kind = self._attr(el, "type", where)
        if kind not in JOINT_TYPES:
            self._fail(
                f"{where} has type '{kind}'",
                f"a serial arm takes joints of type {', '.join(JOINT_TYPES)}",
            )
        ends = {}
        for tag in ("parent", "child"):
            e = el.find(tag)
            if e is None:
                self._fail(f"{where} has no <{tag} link=>", f"name the joint's {tag} link")
            ends[tag] = self._attr(e, "link", f"{where} <{tag}>")
            if ends[tag] not in self.links:
                self._fail(
                    f"{where} names the {tag} link '{ends[tag]}', which is not a <link>",
                    "add the link or correct the name",
                )
        j = {"name": name, "kind": kind, "origin": self._origin(el, where), **ends}
        if kind == "fixed":
            return j
        if el.find("mimic") is not None:
            self._fail(
                f"{where} is a {kind} joint with <mimic>",
                "a serial arm's movable "
                "joints are independent: make the joint fixed or drop the <mimic>",
            )
        a = el.find("axis")
        axis = (
            (1.0, 0.0, 0.0) if a is None else self._numbers(a.get("xyz"), 3, f"{where} <axis xyz=>")
        )
        norm = math.sqrt(sum(v * v for v in axis))
        if norm < 1e-6:
            self._fail(f"{where} has the zero axis {axis}", "give the joint a nonzero <axis xyz=>")
        j["axis"] = tuple(_snap(v / norm) for v in axis)
        if kind == "continuous":
            j["lower"], j["upper"] = -math.pi, math.pi
            return j
        lim = el.find("limit")
        if lim is None or lim.get("lower") is None or lim.get("upper") is None:
            self._fail(
                f"{where} ({kind}) has no <limit lower= upper=>",
                "give the joint's lower and upper limits (or make it continuous)",
            )
        lower = self._number(lim, "lower", f"{where} <limit>")
        upper = self._number(lim, "upper", f"{where} <limit>")
        if not lower < upper:
            self._fail(
                f"{where} has <limit lower={lower:g} upper={upper:g}>",
                "lower must be below upper (a joint that cannot move should be fixed)",
            )
        j["lower"], j["upper"] = lower, upper
        return j

    # ------------------------------------------------------------------ the chain

    def _root(self) -> str:
        roots = [name for name in self.links if name not in self.parent_joint]
        if len(roots) != 1:
            self._fail(
                f"{len(roots)} links are no joint's child ({', '.join(roots) or 'a cycle'})",
                "a URDF's links form one tree with a single root link",
            )
        seen, stack = set(), roots[:]
        while stack:  # every link reachable from the root (else there is a cycle)
            name = stack.pop()
            seen.add(name)
            stack.extend(j["child"] for j in self.children[name])
        if len(seen) != len(self.links):
            cut = sorted(set(self.links) - seen)
            self._fail(
                f"links {cut} are not reachable from the root link '{roots[0]}'",
                "the joints must form a tree without cycles",
            )
        return roots[0]

    def _path(self, root: str, tip: str) -> list[dict]:
        """The joints from ``root`` to ``tip``, in order."""
        path, name = [], tip
        while name != root:
            j = self.parent_joint[name]
            path.append(j)
            name = j["parent"]
        return path[::-1]

    def _default_tip(self, root: str) -> str:
        """The child of the last movable joint of the longest chain of movable joints."""
        best: dict[str, int] = {}  # chain end (a movable joint's child) -> movable joints to it

        def walk(name: str, depth: int):
            for j in self.children[name]:
                d = depth + (j["kind"] in MOVABLE)
                if j["kind"] in MOVABLE:
                    best[j["child"]] = d
                walk(j["child"], d)

        walk(root, 0)
        if not best:
            self._fail(
                "the URDF has no movable joint",
                "a serial arm needs at least one revolute, continuous or prismatic joint",
            )
        top = max(best.values())
        ends = sorted(name for name, d in best.items() if d == top)
        if len(ends) > 1:
            self._fail(
                f"chains to {ends} have {top} movable joints each",
                "name the chain's tip link (tip=...)",
            )
        return ends[0]

    def read(self, srdf: Path | None, tip: str | None) -> ArmModel:
        root = self._root()
        if tip is None:
            tip = self._default_tip(root)
        elif tip not in self.links:
            self._fail(
                f"the tip '{tip}' is not a <link>",
                f"name one of the links ({', '.join(sorted(self.links))})",
            )
        chain = {j["name"] for j in self._path(root, tip) if j["kind"] in MOVABLE}
        if not chain:
            self._fail(
                f"the chain from '{root}' to '{tip}' has no movable joint",
                "name a tip beyond a revolute, continuous or prismatic joint",
            )
        joints, frame_of, off_chain = self._frames(root, chain)
        spheres = []  # (frame, document order, link, centre in the frame, radius)
        for order, name in enumerate(self.links):
            found = self._spheres(name)
            if found and name in off_chain:
                self._fail(
                    f"link '{name}' has collision spheres but moves through the joint "
                    f"'{off_chain[name]}', which is not on the chain from '{root}' to "
                    f"'{tip}'",
                    "name a tip beyond that joint, or make it fixed",
                )
            f, tf = frame_of.get(name, (0, IDENTITY))
            spheres += [
                (f, order, name, tuple(_snap(v) for v in apply(tf, c)), r) for c, r in found
            ]
        if not spheres:
            self._fail(
                "no link has a <collision><geometry><sphere radius=>",
                "spherize the robot's collision geometry (a sphere per <collision>)",
            )
        spheres.sort(key=lambda s: s[:2])  # stable: a link's spheres stay in file order
        links = [s[2] for s in spheres]
        span = {name: (links.index(name), len(links) - links[::-1].index(name)) for name in links}
        disabled = self._disabled(srdf, frame_of)
        blocks = [
            span[a] + span[b]
            for a in span
            for b in span
            if span[a] < span[b]
            and frame_of[a][0] != frame_of[b][0]
            and _pair(a, b) not in disabled
        ]
        blocks = merge_blocks(blocks, [s[0] for s in spheres])
        return ArmModel(
            name=self.root_el.get("name", self.path.stem),
            root=root,
            tip=tip,
            joints=tuple(joints),
            tip_transform=_snapped(frame_of[tip][1]),
            sphere_frames=tuple(s[0] for s in spheres),
            sphere_links=tuple(links),
            sphere_centers=tuple(s[3] for s in spheres),
            sphere_radii=tuple(s[4] for s in spheres),
            self_blocks=blocks,
            disabled_links=tuple(sorted(disabled)),
        )

    def _frames(self, root: str, chain: set[str]):
        """Walks the tree from the root: the chain's joints, every link's ``(frame, pose in
        it)``, and the links hanging off the chain through a movable joint (-> that joint)."""
        joints: list[Joint] = []
        frame_of: dict[str, tuple[int, Transform]] = {root: (0, IDENTITY)}
        off_chain: dict[str, str] = {}
        stack = [root]
        while stack:
            name = stack.pop()
            for j in self.children[name]:
                child = j["child"]
                stack.append(child)
                if name in off_chain:
                    off_chain[child] = off_chain[name]
                elif j["kind"] == "fixed":
                    f, tf = frame_of[name]
                    frame_of[child] = (f, compose(tf, j["origin"]))
                elif j["name"] in chain:
                    f, tf = frame_of[name]
                    joints.append(
                        Joint(
                            j["name"],
                            j["kind"],
                            _snapped(compose(tf, j["origin"])),
                            j["axis"],
                            float(j["lower"]),
                            float(j["upper"]),
                        )
                    )
                    frame_of[child] = (f + 1, IDENTITY)
                else:
                    off_chain[child] = j["name"]
        return joints, frame_of, off_chain

    # ------------------------------------------------------------------ geometry

    def _spheres(self, name: str) -> list[tuple[tuple[float, float, float], float]]:
        out, meshes = [], 0
        for k, col in enumerate(self.links[name].findall("collision")):
            where = f"<link name='{name}'> <collision> #{k + 1}"
            geom = col.find("geometry")
            shapes = [] if geom is None else list(geom)
            if len(shapes) != 1:
                self._fail(
                    f"{where} has {len(shapes)} shapes in <geometry>",
                    "give exactly one <sphere radius=> per <collision>",
                )
            shape = shapes[0]
            if shape.tag == "mesh":
                meshes += 1
                continue
            if shape.tag != "sphere":
                self._fail(
                    f"{where} is a <{shape.tag}>",
                    "a serial arm collides with spheres "
                    "only: replace it by spheres (spherize the link)",
                )
            r = self._number(shape, "radius", f"{where} <sphere>")
            if not r > 0:
                self._fail(f"{where} has <sphere radius={r:g}>", "give a radius > 0")
            out.append((self._origin(col, where)[1], r))
        if out and meshes:
            self._fail(
                f"<link name='{name}'> mixes {len(out)} spheres with {meshes} meshes",
                "spherize the whole link (the meshes would be ignored)",
            )
        return out

    def _disabled(self, srdf: Path | None, frame_of) -> set[tuple[str, str]]:
        pairs = {_pair(j["parent"], j["child"]) for j in self.joints.values()}  # adjacent
        by_frame: dict[int, list[str]] = {}
        for name, (f, _) in frame_of.items():
            by_frame.setdefault(f, []).append(name)
        for names in by_frame.values():  # rigidly attached to the same frame
            pairs |= {_pair(a, b) for a in names for b in names if a != b}
        if srdf is None:
            return pairs
        el = self._parse(srdf, "robot")
        for k, d in enumerate(el.iter("disable_collisions")):
            where = f"<disable_collisions> #{k + 1}"
            names = []
            for key in ("link1", "link2"):
                value = d.get(key)
                if value is None or value not in self.links:
                    self._fail(
                        f"{where} has {key}={value!r}, not a link of {self.path.name}",
                        "name links of the URDF",
                        srdf,
                    )
                names.append(value)
            pairs.add(_pair(*names))
        return pairs


def merge_blocks(blocks, frames) -> tuple[tuple[int, int, int, int], ...]:
    """Merges blocks ``(i0, i1, k0, k1)`` with the same rows and adjacent columns (or the same
    columns and adjacent rows) while each merged range stays on one frame (``frames``: per
    sphere): the same pairs in fewer, larger rectangles, sorted."""
    blocks = set(blocks)

    def one_frame(lo, hi):
        return len(set(frames[lo:hi])) == 1

    merged = True
    while merged:
        merged = False
        for a in sorted(blocks):
            for b in sorted(blocks):
                i0, i1, k0, k1 = a
                if b[:2] == (i0, i1) and b[2] == k1 and one_frame(k0, b[3]):
                    new = (i0, i1, k0, b[3])
                elif b[2:] == (k0, k1) and b[0] == i1 and one_frame(i0, b[1]):
                    new = (i0, b[1], k0, k1)
                else:
                    continue
                blocks -= {a, b}
                blocks.add(new)
                merged = True
                break
            if merged:
                break
    return tuple(sorted(blocks))


def _pair(a: str, b: str) -> tuple[str, str]:
    return (a, b) if a <= b else (b, a)
