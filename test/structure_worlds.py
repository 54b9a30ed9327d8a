"""A mesh the tests write themselves: an I-beam as an OBJ file."""
import numpy as np
import trimesh


def i_beam(path, flange_m=0.4, web_m=0.08, depth_m=0.5, thick_m=0.06, height_m=3.0):
    """An I-beam standing on the ground, its flanges across x at y = +-depth/2, written as
    an OBJ file: its section triangulated by hand (each flange a fan, so that the web's
    corners are vertices of both), extruded up."""
    f, w, d, t = flange_m / 2, web_m / 2, depth_m / 2, thick_m
    section = np.array([(-f, -d), (f, -d), (f, -d + t), (w, -d + t), (-w, -d + t), (-f, -d + t),
                        (f, d), (-f, d), (-f, d - t), (-w, d - t), (w, d - t), (f, d - t)])
    fan = [(0, 1, 2), (0, 2, 3), (0, 3, 4), (0, 4, 5)]
    faces = fan + [(a + 6, b + 6, c + 6) for a, b, c in fan] + [(4, 3, 10), (4, 10, 9)]
    beam = trimesh.creation.extrude_triangulation(section, np.array(faces), height_m)
    assert beam.is_watertight
    beam.export(path)
    return beam


def closest_approach_m(record_dir, scenario, structure_id, vehicle):
    """How near the vehicle came to the structure ``structure_id`` over a recorded flight:
    the least distance from its outline (the four rotor centres at the arms' ends, the arms
    along y, and the tool tip, from the ground-truth odometry) to the structure's box, in
    plan."""
    from uav_tilt_control.obstacles import ObstacleBox
    from uav_tilt_sim.scenario import world_geometry
    from uav_tilt_tools.bag import reader
    geometry, _ = world_geometry(scenario)
    box = next(g for g in geometry if g.cfg.id == structure_id)
    plan_box = ObstacleBox(*box.plan_box())
    outline = np.array([[sx * vehicle.l2_m, sy * vehicle.l1_m, 0.0]
                        for sx in (-1, 1) for sy in (-1, 1)] + [[vehicle.tool_tip_x_m, 0, 0]])
    rec = reader.load_recording(str(record_dir))
    nearest = np.inf
    for p, R in reader.vehicle_poses(rec).values():
        for q in (p + outline @ R.T):
            nearest = min(nearest, plan_box.distance_xy(q[:2]))
    return nearest
