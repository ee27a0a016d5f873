"""Drake physics and rendering of one scene (section III-B).

Collision geometry: each object's bounding box. Drake's point contact between two boxes yields a
single contact point (the deepest), which makes boxes resting on boxes rock and sink. Every box
therefore also carries small contact spheres (radius 1 mm) along its 12 edges (corners plus
``contact_points_per_edge - 1`` points inside each edge), and the table top's edges carry spheres
every ``table_edge_spacing``: resting contact is a set of points on the box boundary, which holds the
boxes 1 mm apart, so the single-point box-box contact only acts as a backstop where the spheres
miss (a thin object sliding over the table edge between spheres). Contact is solved with SAP.

Measured (``sixdpose.generation.checks.resting_penetrations``, 8 demo scenes, seed 7, 5 ms steps):
with box-box and box-table contact filtered out (spheres only) thin objects sank through the table
edge (a knife 11 cm, a hammer's box 13 cm) and boxes overlapped by up to 25 mm; with every pair kept,
the worst table penetration is 6 mm (a 6 g sponge wedged under a 0.7 kg block) and the worst box-box
overlap 4.7 mm (bounding boxes, not meshes), all 8 scenes at rest on the first draw after 1.1-2.7 s of
simulated time, at the same cost. 10 ms steps were faster but let objects sink 3.6 cm. Earlier
measurements: the "lagged"/"similar" approximations, corners and edge midpoints only, or no
table-edge spheres left a third to all scenes moving after 5 s. Registering collision geometry costs
Drake time quadratic in its count, which is why the spheres are not denser.

Rendering: ``RenderEngineVtk`` (EGL, headless) in a render-only SceneGraph kept for the life of a
worker process (:class:`PoolRenderer`): loading the textured meshes into VTK once per worker instead
of once per scene. Depth is rendered by the same engine from the same meshes, so ground truth and
depth agree exactly.
"""

from __future__ import annotations

import builtins
from dataclasses import dataclass

import numpy as np

from ..assets import PhysicalProperties
from ..geometry import X_from
from .config import GenerationConfig
from .scene import ObjectSpec

TABLE_LABEL = 1000
GROUND_LABEL = 1001
EMPTY_LABEL = 32766  #: the label image's value where no geometry is hit
#: Diffuse colours (RGB in [0, 1]) of the table top, its legs and the floor.
TABLE_RGB = (0.55, 0.40, 0.26)
LEG_RGB = (0.45, 0.32, 0.2)
GROUND_RGB = (0.62, 0.62, 0.6)
_CONTACT_SPHERE_RADIUS = 1e-3
_PARKING = np.array([0.0, 0.0, -100.0])  # with x >= 1 km: beyond the far clipping plane


def _contact_points(center: np.ndarray, size: np.ndarray, per_edge: int = 4) -> np.ndarray:
    """Points on the 12 edges of a box: its corners and ``per_edge - 1`` evenly spaced points inside
    each edge, shape (8 + 12 (per_edge - 1), 3)."""
    g = [float(x) for x in np.linspace(-1, 1, per_edge + 1)]
    pts = {(a, b, c) for a in g for b in g for c in g if int(abs(a) == 1) + int(abs(b) == 1) + int(abs(c) == 1) >= 2}
    return center + np.array(sorted(pts)) * size / 2


def _table_edge_points(tx: float, ty: float, z: float, spacing: float) -> np.ndarray:
    """Points every ``spacing`` metres along the four top edges of a table of size tx x ty at height z."""
    pts = []
    for L, W_, axis in ((tx, ty, 0), (ty, tx, 1)):
        n = int(np.ceil(L / spacing))
        for u in np.linspace(-L / 2, L / 2, n + 1):
            for side in (-W_ / 2, W_ / 2):
                pts.append((u, side, z) if axis == 0 else (side, u, z))
    return np.unique(np.round(np.array(pts), 9), axis=0)


@dataclass
class SettleResult:
    """Outcome of :meth:`SceneSimulator.settle`.

    Attributes:
        X_WO: final object poses (list of (4, 4)), in spec order.
        at_rest: every body came to rest within the simulated time.
        sim_time: simulated seconds.
        left: indices of objects that left the scene (parked out of sight, not annotated).
        off_table: indices of objects that ended below the table top (on the ground).
        diverged: the simulation produced non-finite poses at ``sim_time`` (Drake refuses to go on);
            the scene is then re-drawn like one that does not come to rest (``X_WO`` is empty).
    """

    X_WO: list
    at_rest: bool
    sim_time: float
    left: list
    off_table: list
    diverged: bool = False


def _static_scene(cfg: GenerationConfig):
    """Table top, legs and floor as ``(name, X (4x4), box size, rgba, label)``; shared by physics and rendering."""
    tx, ty = cfg.table_size
    thick = 0.04
    leg_h = cfg.table_height - thick
    out = []
    X = X_from(np.eye(3), (0.0, 0.0, cfg.table_height - thick / 2))
    out.append(("table", X, (tx, ty, thick), (*TABLE_RGB, 1.0), TABLE_LABEL))
    for i, (sx, sy) in enumerate([(1, 1), (1, -1), (-1, 1), (-1, -1)]):
        X = X_from(np.eye(3), (sx * (tx / 2 - 0.05), sy * (ty / 2 - 0.05), leg_h / 2))
        out.append((f"leg{i}", X, (0.05, 0.05, leg_h), (*LEG_RGB, 1.0), TABLE_LABEL))
    X = X_from(np.eye(3), (0.0, 0.0, -0.5))  # a thick box: its top face is the floor at z = 0
    out.append(("ground", X, (30.0, 30.0, 1.0), (*GROUND_RGB, 1.0), GROUND_LABEL))
    return out


def _rt(X: np.ndarray):
    from pydrake.math import RigidTransform, RotationMatrix

    return RigidTransform(RotationMatrix(X[:3, :3]), X[:3, 3])


class SceneSimulator:
    """Physics (a MultibodyPlant of collision boxes, no visuals) of one scene, rendered through the
    process-wide :class:`PoolRenderer`.

    Args:
        specs: the scene's objects with initial poses.
        props: physical properties per object name.
        mesh_paths: OBJ path per object name (textures are read from its MTL).
        cfg: generator configuration.
    """

    def __init__(
        self, specs: list[ObjectSpec], props: dict[str, PhysicalProperties], mesh_paths: dict, cfg: GenerationConfig
    ):
        from pydrake.geometry import AddContactMaterial, Box, ProximityProperties, Sphere
        from pydrake.multibody.plant import AddMultibodyPlant, CoulombFriction, MultibodyPlantConfig
        from pydrake.multibody.tree import RotationalInertia, SpatialInertia
        from pydrake.systems.analysis import Simulator
        from pydrake.systems.framework import DiagramBuilder

        self.cfg, self.specs, self.mesh_paths = cfg, specs, mesh_paths
        builder = DiagramBuilder()
        plant, sg = AddMultibodyPlant(
            MultibodyPlantConfig(time_step=cfg.time_step, contact_model="point", discrete_contact_approximation="sap"),
            builder,
        )
        friction = CoulombFriction(0.6, 0.5)

        def proximity():
            p = ProximityProperties()
            AddContactMaterial(None, None, friction, p)
            return p

        W = plant.world_body()
        for name, X, size, _, _ in _static_scene(cfg):
            plant.RegisterCollisionGeometry(W, _rt(X), Box(*size), name, proximity())
        # spheres along the table top's edges, so an object's face resting on an edge is supported
        for j, p in enumerate(_table_edge_points(*cfg.table_size, cfg.table_height, cfg.table_edge_spacing)):
            plant.RegisterCollisionGeometry(W, _rt(_translation(p)), Sphere(0.002), f"tedge{j}", proximity())
        self.bodies = []
        for k, s in enumerate(specs):
            pr = props[s.name]
            inst = plant.AddModelInstance(f"obj{k}")
            Ic = pr.inertia
            M = SpatialInertia.MakeFromCentralInertia(
                pr.mass, pr.com, RotationalInertia(Ic[0, 0], Ic[1, 1], Ic[2, 2], Ic[0, 1], Ic[0, 2], Ic[1, 2])
            )
            body = plant.AddRigidBody(f"{s.name}_{s.inst}", inst, M)
            plant.RegisterCollisionGeometry(
                body, _rt(_translation(pr.box_center)), Box(*pr.box_size), f"box{k}", proximity()
            )
            for j, p in enumerate(_contact_points(pr.box_center, pr.box_size, cfg.contact_points_per_edge)):
                plant.RegisterCollisionGeometry(
                    body, _rt(_translation(p)), Sphere(_CONTACT_SPHERE_RADIUS), f"pt{k}_{j}", proximity()
                )
            self.bodies.append(body)
        plant.Finalize()

        self.plant = plant
        self.diagram = builder.Build()
        self.simulator = Simulator(self.diagram)
        self.context = self.simulator.get_mutable_context()
        self.plant_context = plant.GetMyMutableContextFromRoot(self.context)
        for body, s in zip(self.bodies, specs, strict=True):
            plant.SetFreeBodyPose(self.plant_context, body, _rt(s.X_WO))
        self._result: SettleResult | None = None

    def settle(self) -> SettleResult:
        """Simulate until every body is at rest (checked every 0.1 s) or ``cfg.sim_time`` elapses."""
        cfg, plant, pc = self.cfg, self.plant, self.plant_context
        self.simulator.Initialize()
        t, still = 0.0, 0
        at_rest = False
        while t < cfg.sim_time - 1e-9:
            t = builtins.min(t + 0.1, cfg.sim_time)
            try:
                self.simulator.AdvanceTo(t)
            except RuntimeError as e:  # the contact solve diverged (NaN poses): this draw is unusable
                if "non-finite" not in str(e):
                    raise
                self._result = SettleResult([], False, t, [], [], diverged=True)
                return self._result
            v = plant.GetVelocities(pc)
            still = still + 1 if (v.size == 0 or float(np.abs(v).max()) < cfg.rest_speed) else 0
            if still >= 2:
                at_rest = True
                break
        X_WO, left, off = [], [], []
        for k, body in enumerate(self.bodies):
            X = plant.EvalBodyPoseInWorld(pc, body).GetAsMatrix4()
            p = X[:3, 3]
            if p[2] < -0.05 or np.hypot(p[0], p[1]) > cfg.scene_radius or not np.all(np.isfinite(X)):
                left.append(k)  # not rendered, not annotated
            elif p[2] < cfg.table_height - 0.05:
                off.append(k)
            X_WO.append(X)
        self._result = SettleResult(X_WO, at_rest, t, left, off)
        return self._result

    def render(self, X_WC: np.ndarray):
        """Render the settled scene from camera pose ``X_WC`` (4, 4); see :meth:`PoolRenderer.render`."""
        if self._result is None:
            raise RuntimeError("settle() the scene before rendering it")
        r = PoolRenderer.get(self.cfg)
        if r.owner is not self:
            r.set_scene(self.specs, self._result.X_WO, self._result.left, self.mesh_paths)
            r.owner = self
        return r.render(X_WC)


def _translation(p) -> np.ndarray:
    return X_from(np.eye(3), p)


class PoolRenderer:
    """A render-only SceneGraph with ``RenderEngineVtk`` (EGL), kept for the life of the process.

    Loading textured meshes into VTK is the costly part of building a scene, so each object instance
    slot ``(name, inst)`` gets a frame once and its mesh the first time a scene uses it; slots unused by
    the current scene are parked 1 km away, beyond the far clipping plane, so they produce no pixels.
    Labels are mapped back to the scene's numbering: object k of the scene has label k + 1.
    """

    _instance: PoolRenderer | None = None
    _key = None

    @classmethod
    def get(cls, cfg: GenerationConfig) -> PoolRenderer:
        """The process-wide renderer for ``cfg``'s camera and static scene (rebuilt if they change)."""
        key = (cfg.camera, cfg.table_size, cfg.table_height, cfg.max_instances, tuple(sorted(_ALL_NAMES.items())))
        if cls._instance is None or cls._key != key:
            cls._instance, cls._key = cls(cfg), key
        return cls._instance

    def __init__(self, cfg: GenerationConfig):
        from pydrake.geometry import (
            Box,
            ClippingRange,
            ColorRenderCamera,
            DepthRange,
            DepthRenderCamera,
            GeometryInstance,
            MakeRenderEngineVtk,
            PerceptionProperties,
            RenderCameraCore,
            RenderEngineVtkParams,
            RenderLabel,
            Rgba,
            SceneGraph,
        )
        from pydrake.systems.framework import DiagramBuilder

        self.cfg = cfg
        builder = DiagramBuilder()
        sg = builder.AddSystem(SceneGraph())
        sg.AddRenderer("vtk", MakeRenderEngineVtk(RenderEngineVtkParams(backend="EGL")))
        self.source = sg.RegisterSource("sixdpose_pool")
        for name, X, size, rgba, label in _static_scene(cfg):
            gi = GeometryInstance(_rt(X), Box(*size), name)
            pp = PerceptionProperties()
            pp.AddProperty("phong", "diffuse", Rgba(*rgba))
            pp.AddProperty("label", "id", RenderLabel(label))
            gi.set_perception_properties(pp)
            sg.RegisterAnchoredGeometry(self.source, gi)
        self.sg = sg
        self._frames: dict[tuple[str, int], object] = {}
        self._slots: dict[tuple[str, int], int] = {}
        self._loaded: set = set()
        self._builder = builder
        self._diagram = None
        cam = cfg.camera
        core = RenderCameraCore("vtk", camera_info(cfg), ClippingRange(0.01, cam.far + 1), _rt(np.eye(4)))
        self._color = ColorRenderCamera(core, False)
        self._depth = DepthRenderCamera(core, DepthRange(cam.near, cam.far))
        self._lut = None
        self.owner = None  #: the SceneSimulator whose scene is placed
        self._GeometryInstance, self._PerceptionProperties, self._RenderLabel = (
            GeometryInstance,
            PerceptionProperties,
            RenderLabel,
        )

    def _ensure_frames(self, names):
        """Register frames for every slot of ``names`` (before the diagram is built)."""
        from pydrake.geometry import GeometryFrame

        for name in sorted(names):
            for i in range(self.cfg.max_instances):
                if (name, i) not in self._frames:
                    self._slots[(name, i)] = len(self._slots)
                    self._frames[(name, i)] = self.sg.RegisterFrame(self.source, GeometryFrame(f"{name}_{i}"))

    def set_scene(self, specs: list[ObjectSpec], X_WO: list, left: list, mesh_paths: dict) -> None:
        """Place the scene's objects (final poses ``X_WO``; indices in ``left`` are not shown)."""
        from pydrake.geometry import FramePoseVector, Mesh

        if self._diagram is None:
            self._ensure_frames(mesh_paths_all(mesh_paths))
            self._diagram = self._builder.Build()
            self._context = self._diagram.CreateDefaultContext()
            self._sg_context = self.sg.GetMyMutableContextFromRoot(self._context)
        unknown = [s.name for s in specs if (s.name, s.inst) not in self._frames]
        if unknown:
            raise RuntimeError(f"objects not in the renderer's catalogue: {sorted(set(unknown))}")
        lut = np.zeros(1 << 15, dtype=np.int32)
        lut[TABLE_LABEL], lut[GROUND_LABEL] = TABLE_LABEL, GROUND_LABEL
        lut[EMPTY_LABEL] = EMPTY_LABEL
        poses = FramePoseVector()
        placed = {}
        for k, s in enumerate(specs):
            if k not in left:
                placed[(s.name, s.inst)] = (k, X_WO[k])
        for slot, fid in self._frames.items():
            j = self._slots[slot]
            if slot in placed:
                k, X = placed[slot]
                if slot not in self._loaded:
                    gi = self._GeometryInstance(
                        _rt(np.eye(4)), Mesh(str(mesh_paths[slot[0]])), f"mesh_{slot[0]}_{slot[1]}"
                    )
                    pp = self._PerceptionProperties()
                    pp.AddProperty("label", "id", self._RenderLabel(j + 1))
                    gi.set_perception_properties(pp)
                    self.sg.RegisterGeometry(self._sg_context, self.source, fid, gi)
                    self._loaded.add(slot)
                lut[j + 1] = k + 1
                poses.set_value(fid, _rt(X))
            else:
                poses.set_value(fid, _rt(_translation(_PARKING + [1000.0 + 3.0 * j, 0.0, 0.0])))
        self.sg.get_source_pose_port(self.source).FixValue(self._sg_context, poses)
        self._lut = lut

    def render(self, X_WC: np.ndarray):
        """Render from camera pose ``X_WC`` (4, 4).

        Returns:
            rgb (H, W, 3) uint8, depth (H, W) float32 metres (0.0 = no surface within range),
            label (H, W) int32 (scene object k has label k + 1; table 1000, ground 1001, empty 32766).
        """
        cam = self.cfg.camera
        qo = self.sg.get_query_output_port().Eval(self._sg_context)
        frame = self.sg.world_frame_id()
        X = _rt(X_WC)
        rgb = np.array(qo.RenderColorImage(self._color, frame, X).data, copy=True)[..., :3]
        depth = np.array(qo.RenderDepthImage(self._depth, frame, X).data, copy=True)[..., 0].astype(np.float32)
        depth[~np.isfinite(depth) | (depth < cam.near) | (depth > cam.far)] = 0.0
        label = np.array(qo.RenderLabelImage(self._color, frame, X).data, copy=True)[..., 0].astype(np.int32)
        return rgb, depth, self._lut[label]


_ALL_NAMES: dict = {}


def set_catalogue(mesh_paths) -> None:
    """Declare every object the process may render (replacing the previous declaration): name -> mesh
    path (or just names, rendered with the paths given to :meth:`PoolRenderer.set_scene`). Frames are
    made for all of them at once; a changed catalogue rebuilds the renderer (:meth:`PoolRenderer.get`)."""
    _ALL_NAMES.clear()
    if isinstance(mesh_paths, dict):
        _ALL_NAMES.update({str(k): str(getattr(v, "obj_path", v)) for k, v in mesh_paths.items()})
    else:
        _ALL_NAMES.update({str(k): "" for k in mesh_paths})


def mesh_paths_all(mesh_paths: dict) -> set:
    """Names to make renderer frames for: the declared catalogue plus those of ``mesh_paths``."""
    return set(_ALL_NAMES) | set(mesh_paths)


def camera_info(cfg: GenerationConfig):
    """Drake ``CameraInfo`` of ``cfg.camera``: from ``intrinsics`` (fx, fy, cx, cy) when given, else
    from the vertical field of view. The renderer uses it and :func:`intrinsics` derives K from it, so
    the images and ``cam_K`` cannot disagree.

    Drake's principal point lies half a pixel from ours (see :func:`intrinsics`), so explicit
    intrinsics are passed to Drake as ``(cx + 0.5, cy + 0.5)``.
    """
    from pydrake.systems.sensors import CameraInfo

    cam = cfg.camera
    if cam.intrinsics is not None:
        fx, fy, cx, cy = cam.intrinsics
        return CameraInfo(cam.width, cam.height, fx, fy, cx + 0.5, cy + 0.5)
    return CameraInfo(cam.width, cam.height, np.deg2rad(cam.fov_y_deg))


def intrinsics(cfg: GenerationConfig) -> np.ndarray:
    """Camera matrix K (3, 3) of the rendered images (:func:`camera_info`), in the convention used
    everywhere here: pixel (u, v) (column, row index) has its centre at integer coordinates, so it
    back-projects with depth z to ``((u - cx) z / fx, (v - cy) z / fy, z)``.

    ``CameraInfo`` reports the principal point ``(width/2 - 0.5, height/2 - 0.5)`` in a convention
    where pixel u spans [u, u + 1) (centre at u + 0.5); measured on rendered depth (see
    ``tests/test_generation.py::test_gt_exact``), the integer-centre principal point is therefore
    ``(width/2 - 1, height/2 - 1)``: ours is Drake's minus 0.5. Using Drake's value directly shifts
    back-projected points by half a pixel (about 0.8 mm at 1 m). With ``camera.intrinsics`` set, K is
    exactly those values.
    """
    info = camera_info(cfg)
    return np.array(
        [[info.focal_x(), 0, info.center_x() - 0.5], [0, info.focal_y(), info.center_y() - 0.5], [0, 0, 1.0]]
    )
