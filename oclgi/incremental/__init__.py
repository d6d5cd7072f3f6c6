"""Incremental updates: sessions that keep every path segment and, after a
move, re-trace only the paths it touches.

    protocol.py            what every session offers (move, irradiance, render, set_camera,
                           set_estimator, set_photons, parameters, close)
    open_session.py        the kind of session a method needs
    attached_points.py     given query points on movable objects follow them
    light_session.py       a light moved among an animation's positions by path reuse
    segment_store.py       the stored paths and the update steps (find, subtract, re-trace, add)
    session.py             DETP and Impact Count sessions over sensors or a camera
    dynamic_view.py        a camera session's static and dynamic points
    photon_map_session.py  Photon Maps under moves (practical and exact updates)
    animate.py             ``oclgi animate``: poses along a path, frames and timings
"""
