"""Keep a compiled model consistent after its bodies' geoms or masses are edited at reset.

MuJoCo's compiler derives inertias, bounding volumes and the ``mj_setConst`` constants from
geoms and masses; editing ``geom_size`` or ``body_mass`` in a compiled model leaves them
stale. We compile each edited body alone (same geoms, same compiler bounds) and copy the
derived fields back, as myosuite's tasks do, so our model equals theirs after every reset.
"""

from __future__ import annotations

from collections.abc import Iterable

import mujoco
import numpy as np

_BOUND_OPTIONS = ("boundmass", "boundinertia", "balanceinertia")


def refresh_bodies(model: mujoco.MjModel, spec: mujoco.MjSpec, body_ids: Iterable[int],
                   scratch: mujoco.MjData) -> None:
    """Recompute the derived fields of ``body_ids`` (primitive geoms only), then ``mj_setConst``.

    A body with an explicit inertial keeps its inertia shape, scaled with its current mass;
    a body welded to the world keeps its compiled inertial frame.
    """
    for body_id in body_ids:
        _refresh_body(model, spec, int(body_id))
    mujoco.mj_setConst(model, scratch)


def _refresh_body(model: mujoco.MjModel, spec: mujoco.MjSpec, body_id: int) -> None:
    source = spec.bodies[body_id]
    static = model.body_weldid[body_id] == 0
    tiny = mujoco.MjSpec()
    tiny.compiler.inertiagrouprange = spec.compiler.inertiagrouprange
    for option in _BOUND_OPTIONS:
        setattr(tiny.compiler, option, getattr(spec.compiler, option))
    body = tiny.worldbody.add_body()
    first = int(model.body_geomadr[body_id])
    geom_ids = list(range(first, first + int(model.body_geomnum[body_id])))
    for gid, geom in zip(geom_ids, source.geoms):
        body.add_geom(type=mujoco.mjtGeom(int(model.geom_type[gid])), size=model.geom_size[gid],
                      pos=model.geom_pos[gid], quat=model.geom_quat[gid], group=int(model.geom_group[gid]),
                      contype=int(model.geom_contype[gid]), conaffinity=int(model.geom_conaffinity[gid]),
                      density=geom.density, mass=geom.mass, typeinertia=geom.typeinertia)
    site_ids = np.flatnonzero(model.site_bodyid == body_id)
    for sid in site_ids:
        body.add_site(pos=model.site_pos[sid], quat=model.site_quat[sid])
    body.explicitinertial = True
    body.mass = model.body_mass[body_id]
    body.ipos = model.body_ipos[body_id]
    body.iquat = model.body_iquat[body_id]
    if static:
        body.inertia = model.body_inertia[body_id]
    else:
        body.inertia = source.inertia * (model.body_mass[body_id] / source.mass)
    compiled = tiny.compile()
    model.geom_aabb[geom_ids] = compiled.geom_aabb
    model.geom_rbound[geom_ids] = compiled.geom_rbound
    model.geom_sameframe[geom_ids] = compiled.geom_sameframe
    model.site_sameframe[site_ids] = compiled.site_sameframe
    if not static:
        model.body_inertia[body_id] = compiled.body_inertia[1]
        model.body_ipos[body_id] = compiled.body_ipos[1]
        model.body_iquat[body_id] = compiled.body_iquat[1]
        model.body_sameframe[body_id] = compiled.body_sameframe[1]
    adr, num = int(model.body_bvhadr[body_id]), int(model.body_bvhnum[body_id])
    if num != compiled.body_bvhnum[1]:
        raise ValueError(f"body {model.body(body_id).name!r} changed its set of colliding geoms")
    nodes = slice(adr, adr + num)
    model.bvh_aabb[nodes] = compiled.bvh_aabb
    model.bvh_child[nodes] = compiled.bvh_child
    model.bvh_depth[nodes] = compiled.bvh_depth
    node_geom = compiled.bvh_nodeid.copy()  # leaves hold geom ids: map them back
    leaf = node_geom >= 0
    node_geom[leaf] = np.asarray(geom_ids)[node_geom[leaf]]
    model.bvh_nodeid[nodes] = node_geom


def euler_to_quat(euler: np.ndarray) -> np.ndarray:
    """Intrinsic X-Y'-Z'' Euler angles (rad) to a MuJoCo quaternion (w, x, y, z)."""
    ai, aj, ak = euler[2] / 2, -euler[1] / 2, euler[0] / 2
    si, sj, sk = np.sin(ai), np.sin(aj), np.sin(ak)
    ci, cj, ck = np.cos(ai), np.cos(aj), np.cos(ak)
    cc, cs, sc, ss = ci * ck, ci * sk, si * ck, si * sk
    return np.array([cj * cc + sj * ss, cj * cs - sj * sc, -(cj * ss + sj * cc), cj * sc - sj * cs])


_EPS4 = np.finfo(np.float64).eps * 4.0


def mat_to_euler(mat: np.ndarray) -> np.ndarray:
    """A 3x3 rotation matrix to intrinsic X-Y'-Z'' Euler angles (rad), as myosuite computes them."""
    cy = np.sqrt(mat[2, 2] * mat[2, 2] + mat[1, 2] * mat[1, 2])
    if cy > _EPS4:
        return np.array([-np.arctan2(mat[1, 2], mat[2, 2]), -np.arctan2(-mat[0, 2], cy),
                         -np.arctan2(mat[0, 1], mat[0, 0])])
    return np.array([0.0, -np.arctan2(-mat[0, 2], cy), -np.arctan2(-mat[1, 0], mat[1, 1])])


def quat_to_mat(quat: np.ndarray) -> np.ndarray:
    """A MuJoCo quaternion (w, x, y, z) to its 3x3 rotation matrix."""
    mat = np.empty(9)
    mujoco.mju_quat2Mat(mat, np.asarray(quat, dtype=np.float64))
    return mat.reshape(3, 3)
