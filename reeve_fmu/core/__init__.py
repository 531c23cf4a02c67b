"""The engine: scene files -> compiled Model -> element kernels -> assembly -> integrators.

scene      TOML schema and validation (SceneError names the file and key)
geometry   rope-sheave tangent points (closed form in a plane, Newton in 3D)
traction   rope-groove friction (EN 81-50 equivalent friction, Euler-Eytelwein limit)
profiles   motion profiles (S-curves, speed tables) as piecewise cubics
builder/   the build steps from a Scene to the Model's arrays
model      build an immutable Model (arrays) from a Scene; State holds what evolves
kernel     the compiled code's view of the Model, State and work arrays (field tables, input layout)
elements/  element kernels: linear, cubic (ANCF), torsion
contact    contact laws: rope creep on the rim, brake and groove friction, buffers
bodies     nonlinear rows of rotating bodies and exact tangent points; rigid: their inertia
system     assembly of M(q) qdd = Q(q, qdot, t, u) and the outputs
solver/    generalized-alpha (one Newton step, dense or banded), statics, scipy reference methods; Simulator
results    CSV and overview plots with the documented output names
"""
