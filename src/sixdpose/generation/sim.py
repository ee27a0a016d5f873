"""Drake physics and rendering of one scene (section III-B).

Collision geometry: each object's bounding box. Drake's point contact between two boxes yields a
single contact point, which makes resting boxes rock and sink. Instead every box carries small
contact spheres along its 12 edges (corners plus ``contact_points_per_edge - 1`` points inside each
edge) and box-box and box-table pairs are filtered out: the boxes are passive surfaces that the
other bodies' spheres touch, so resting contact is a set of points on the box boundary and objects
neither sink into the table nor into each other. The table top's edges carry spheres too, so an
object lying across the edge is supported. Contact is solved with SAP (``discrete_contact_approximation
= "sap"``), which damps the rocking the "lagged" approximation leaves. Measured on the first 8
demo scenes (5 ms steps): with 3 points per edge (corners + 2 inside) and table-edge spheres every
5 cm, 7 of 8 at rest after about 1.6 s of simulated time (4 per edge: also 7/8, 25% slower to build;
a scene that does not rest is re-drawn); with corners and edge midpoints only, or without the
table-edge spheres, or with the lagged/similar approximations, a third to all of the scenes were
still moving after 5 s. Registering collision geometry costs Drake time quadratic in its count,
which is why the spheres are not denser. The table is a box on four legs, the floor the top of a thick
box at z = 0.

Rendering: ``RenderEngineVtk`` (EGL, headless). Depth is rendered by the same engine from the same
meshes, so ground truth and depth agree exactly.
"""

from __future__ import annotations

import builtins
from dataclasses import dataclass

import numpy as np

from ..assets import PhysicalProperties
from .config import GenerationConfig
from .scene import ObjectSpec

TABLE_LABEL = 1000
GROUND_LABEL = 1001
_CONTACT_SPHERE_RADIUS = 1e-3
_PARKING = np.array([0.0, 0.0, -50.0])  # out of sight, under the ground


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
    """

    X_WO: list
    at_rest: bool
    sim_time: float
    left: list
    off_table: list


class SceneSimulator:
    """A Drake diagram (MultibodyPlant + SceneGraph + VTK renderer) for one scene.

    Args:
        specs: the scene's objects with initial poses.
        props: physical properties per object name.
        mesh_paths: OBJ path per object name (textures are read from its MTL).
        cfg: generator configuration.
    """

    def __init__(self, specs: list[ObjectSpec], props: dict[str, PhysicalProperties], mesh_paths: dict, cfg: GenerationConfig):
        from pydrake.geometry import (
            Box,
            CollisionFilterDeclaration,
            GeometryInstance,
            GeometrySet,
            IllustrationProperties,
            MakeRenderEngineVtk,
            Mesh,
            PerceptionProperties,
            ProximityProperties,
            RenderEngineVtkParams,
            RenderLabel,
            Rgba,
            Sphere,
        )
        from pydrake.math import RigidTransform, RotationMatrix
        from pydrake.multibody.plant import (
            AddMultibodyPlant,
            CoulombFriction,
            MultibodyPlantConfig,
        )
        from pydrake.geometry import AddContactMaterial
        from pydrake.multibody.tree import RotationalInertia, SpatialInertia
        from pydrake.systems.analysis import Simulator
        from pydrake.systems.framework import DiagramBuilder

        self.cfg, self.specs = cfg, specs
        self._RigidTransform, self._RotationMatrix = RigidTransform, RotationMatrix
        builder = DiagramBuilder()
        plant, sg = AddMultibodyPlant(
            MultibodyPlantConfig(time_step=cfg.time_step, contact_model="point", discrete_contact_approximation="sap"),
            builder,
        )
        sg.AddRenderer("vtk", MakeRenderEngineVtk(RenderEngineVtkParams(backend="EGL")))
        friction = CoulombFriction(0.6, 0.5)

        def proximity():
            p = ProximityProperties()
            AddContactMaterial(None, None, friction, p)
            return p

        def visual(body, X, shape, name, label, rgba=None):
            gi = GeometryInstance(X, shape, name)
            pp, ip = PerceptionProperties(), IllustrationProperties()
            if rgba is not None:
                pp.AddProperty("phong", "diffuse", Rgba(*rgba))
                ip.AddProperty("phong", "diffuse", Rgba(*rgba))
            pp.AddProperty("label", "id", RenderLabel(label))
            gi.set_perception_properties(pp)
            gi.set_illustration_properties(ip)
            plant.RegisterVisualGeometry(body, gi)

        W = plant.world_body()
        tx, ty = cfg.table_size
        thick = 0.04
        X_table = RigidTransform([0.0, 0.0, cfg.table_height - thick / 2])
        static = [plant.RegisterCollisionGeometry(W, X_table, Box(tx, ty, thick), "table", proximity())]
        # spheres along the table top's edges, so an object's face resting on an edge is supported
        for j, p in enumerate(_table_edge_points(tx, ty, cfg.table_height, cfg.table_edge_spacing)):
            static.append(plant.RegisterCollisionGeometry(W, RigidTransform(p), Sphere(0.002), f"tedge{j}", proximity()))
        visual(W, X_table, Box(tx, ty, thick), "table", TABLE_LABEL, (0.55, 0.40, 0.26, 1.0))
        leg_h = cfg.table_height - thick
        for i, (sx, sy) in enumerate([(1, 1), (1, -1), (-1, 1), (-1, -1)]):
            X_leg = RigidTransform([sx * (tx / 2 - 0.05), sy * (ty / 2 - 0.05), leg_h / 2])
            static.append(plant.RegisterCollisionGeometry(W, X_leg, Box(0.05, 0.05, leg_h), f"leg{i}", proximity()))
            visual(W, X_leg, Box(0.05, 0.05, leg_h), f"leg{i}", TABLE_LABEL, (0.45, 0.32, 0.2, 1.0))
        X_ground = RigidTransform([0, 0, -0.5])  # a thick box: its top face is the floor at z = 0
        static.append(plant.RegisterCollisionGeometry(W, X_ground, Box(30, 30, 1.0), "ground", proximity()))
        visual(W, X_ground, Box(30, 30, 1.0), "ground", GROUND_LABEL, (0.62, 0.62, 0.6, 1.0))

        self.bodies = []
        boxes = []
        for k, s in enumerate(specs):
            pr = props[s.name]
            inst = plant.AddModelInstance(f"obj{k}")
            I = pr.inertia
            M = SpatialInertia.MakeFromCentralInertia(
                pr.mass, pr.com, RotationalInertia(I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2])
            )
            body = plant.AddRigidBody(f"{s.name}_{s.inst}", inst, M)
            boxes.append(plant.RegisterCollisionGeometry(body, RigidTransform(pr.box_center), Box(*pr.box_size), f"box{k}", proximity()))
            for j, p in enumerate(_contact_points(pr.box_center, pr.box_size, cfg.contact_points_per_edge)):
                plant.RegisterCollisionGeometry(body, RigidTransform(p), Sphere(_CONTACT_SPHERE_RADIUS), f"pt{k}_{j}", proximity())
            visual(body, RigidTransform(), Mesh(str(mesh_paths[s.name])), f"mesh{k}", k + 1)
            self.bodies.append(body)
        plant.Finalize()
        # Boxes are passive: only the contact spheres of other bodies touch them.
        box_set = GeometrySet(boxes)
        sg.collision_filter_manager().Apply(
            CollisionFilterDeclaration().ExcludeWithin(box_set).ExcludeBetween(box_set, GeometrySet(static))
        )
        self.plant, self.scene_graph = plant, sg
        self.diagram = builder.Build()
        self.simulator = Simulator(self.diagram)
        self.context = self.simulator.get_mutable_context()
        self.plant_context = plant.GetMyMutableContextFromRoot(self.context)
        for body, s in zip(self.bodies, specs):
            plant.SetFreeBodyPose(self.plant_context, body, self._X(s.X_WO))

    def _X(self, X: np.ndarray):
        return self._RigidTransform(self._RotationMatrix(X[:3, :3]), X[:3, 3])

    def settle(self) -> SettleResult:
        """Simulate until every body is at rest (checked every 0.1 s) or ``cfg.sim_time`` elapses."""
        cfg, plant, pc = self.cfg, self.plant, self.plant_context
        self.simulator.Initialize()
        t, still = 0.0, 0
        at_rest = False
        while t < cfg.sim_time - 1e-9:
            t = builtins.min(t + 0.1, cfg.sim_time)
            self.simulator.AdvanceTo(t)
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
                left.append(k)
                X = np.eye(4)
                X[:3, 3] = _PARKING + np.array([3.0 * k, 0, 0])
                plant.SetFreeBodyPose(pc, body, self._X(X))
            elif p[2] < cfg.table_height - 0.05:
                off.append(k)
            X_WO.append(X)
        if left:  # the parked bodies must not move during rendering; velocities are irrelevant then
            pass
        return SettleResult(X_WO, at_rest, t, left, off)

    def render(self, X_WC: np.ndarray):
        """Render from camera pose ``X_WC`` (4, 4).

        Returns:
            rgb (H, W, 3) uint8, depth (H, W) float32 metres (0.0 = no surface within range),
            label (H, W) int32 (object k has label k + 1; table 1000, ground 1001, empty 32766).
        """
        from pydrake.geometry import ClippingRange, ColorRenderCamera, DepthRange, DepthRenderCamera, RenderCameraCore
        from pydrake.systems.sensors import CameraInfo

        cam = self.cfg.camera
        if not hasattr(self, "_cams"):
            core = RenderCameraCore(
                "vtk", CameraInfo(cam.width, cam.height, np.deg2rad(cam.fov_y_deg)), ClippingRange(0.01, cam.far + 1), self._X(np.eye(4))
            )
            self._cams = (ColorRenderCamera(core, False), DepthRenderCamera(core, DepthRange(cam.near, cam.far)))
        color_cam, depth_cam = self._cams
        sg = self.scene_graph
        qo = sg.get_query_output_port().Eval(sg.GetMyContextFromRoot(self.context))
        frame = sg.world_frame_id()
        X = self._X(X_WC)
        rgb = np.array(qo.RenderColorImage(color_cam, frame, X).data, copy=True)[..., :3]
        depth = np.array(qo.RenderDepthImage(depth_cam, frame, X).data, copy=True)[..., 0].astype(np.float32)
        depth[~np.isfinite(depth) | (depth < cam.near) | (depth > cam.far)] = 0.0
        label = np.array(qo.RenderLabelImage(color_cam, frame, X).data, copy=True)[..., 0].astype(np.int32)
        return rgb, depth, label


def intrinsics(cfg: GenerationConfig) -> np.ndarray:
    """Camera matrix K (3, 3) of the images rendered with ``CameraInfo(width, height, fov_y)``, in the
    convention used everywhere here: pixel (u, v) (column, row index) has its centre at integer
    coordinates, so it back-projects with depth z to ``((u - cx) z / fx, (v - cy) z / fy, z)``.

    ``CameraInfo`` reports the principal point ``(width/2 - 0.5, height/2 - 0.5)`` in a convention
    where pixel u spans [u, u + 1) (centre at u + 0.5); measured on rendered depth (see
    ``tests/test_generation.py::test_gt_exact``), the integer-centre principal point is therefore
    ``(width/2 - 1, height/2 - 1)``. Using Drake's value directly shifts back-projected points by half
    a pixel (about 0.8 mm at 1 m).
    """
    from pydrake.systems.sensors import CameraInfo

    cam = cfg.camera
    info = CameraInfo(cam.width, cam.height, np.deg2rad(cam.fov_y_deg))
    return np.array(
        [[info.focal_x(), 0, info.center_x() - 0.5], [0, info.focal_y(), info.center_y() - 0.5], [0, 0, 1.0]]
    )
