"""The model builder: a validated Scene compiled in named steps into the arrays of a Model.

model.build_model runs the steps in this order; each is a function of the shared BuildState
(state.py), which holds the generalized coordinates, the rope nodes and elements and the
constant q-level terms as they are collected:

    bodies.add_body_coordinates    bodies and joints: one coordinate per free body axis
    routes.stop_geometry           supports and routes: centre, radius, axis, wrap sense per route stop
    routes.span_tangents           tangents: the touching points of every span
    routes.wrap_table              wraps: angle and material length per sheave
    spans.add_rope                 spans and wraps: sheave coordinates, span nodes, W2 wrap elements
    bodies.add_body_inertia        body mass, weight and damping
    coordinates.node_arrays        coordinates: p = B q + Bpar par + c0, element maps, M0, F0
    elimination.drive_setup        elimination: the prescribed drive coordinate, the statics sets
    outputs.output_table           outputs: names and how each is computed
    assemble.kernel_arrays         the Kernel arrays of the compiled step
"""
