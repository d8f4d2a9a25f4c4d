"""The four constrained models of issue 23 (docs/constraints.md, worked examples): each multiplier
against its closed form.  Used by tests/test_constraint_forces.py and tests/test_units_paths.py."""
ATWOOD = """
model Atwood "two masses on a string over a massive pulley (a uniform disk) that does not slip"
  parameter Real m1(unit = "kg") = 3;
  parameter Real m2(unit = "kg") = 2;
  parameter Real M(unit = "kg") = 1 "pulley";
  parameter Real R(unit = "m") = 0.1 "pulley radius";
  parameter Real L(unit = "m") = 2 "string length below the pulley";
  parameter Real g(unit = "m/s2") = 9.81;
  Gravity gravity(g = {0, -g, 0});
  PointMass b1(m = m1);
  PointMass b2(m = m2);
  Disk pulley(m = M, R = R);
  Prismatic hang1(parent = world, child = b1, axis = {0, -1, 0}, s(start = 1));
  Prismatic hang2(parent = world, child = b2, axis = {0, -1, 0}, s(start = 1, fixed = false));
  Revolute axle(parent = world, child = pulley, axis = {0, 0, 1}, phi(start = 10, fixed = false));
equation
  hang1.s + hang2.s = L "string";
  hang1.s - R*axle.phi = 0 "grip";
end Atwood;
"""
DISK = """
model RollingDisk "a uniform disk rolling without slipping down an incline (x down the slope)"
  parameter Real m(unit = "kg") = 2;
  parameter Real R(unit = "m") = 0.3;
  parameter Real g(unit = "m/s2") = 9.81;
  parameter Real alpha(unit = "deg") = 30 "slope";
  Gravity gravity(g = {g*sin(alpha), -g*cos(alpha), 0});
  Disk disk(m = m, R = R);
  Planar p(parent = world, child = disk, axis = {0, 0, 1});
  output Real s(unit = "m") = p.x;
equation
  p.x + R*p.phi = 0 "rolling";
  p.y = 0 "contact";
end RollingDisk;
"""
LINKAGE = """
model Linkage "two bars A-B-C hinged at A above a floor; the end C slides on the floor (y = 0)"
  parameter Real m1(unit = "kg") = 1;
  parameter Real m2(unit = "kg") = 1;
  parameter Real L1(unit = "m") = 1;
  parameter Real L2(unit = "m") = 1.5;
  parameter Real H(unit = "m") = 2 "height of A";
  parameter Real P(unit = "N") = 10 "load at C";
  parameter Real g(unit = "m/s2") = 9.81;
  Gravity gravity(g = {0, -g, 0});
  Point A(body = world, r = {0, H, 0});
  Rod ab(m = m1, L = L1, axis = {0, -1, 0});
  Rod bc(m = m2, L = L2, axis = {0, -1, 0});
  Revolute jA(parent = A, child = ab.a, axis = {0, 0, 1}, phi(start = 0.1, fixed = false));
  Revolute jB(parent = ab.b, child = bc.a, axis = {0, 0, 1}, phi(start = 0.7, fixed = false));
  Force load(point = bc.b, F = {0, -P, 0});
  output Real N[3] = constraint_force(floor, bc) "the floor's force on the bar at C, world axes";
  output Real power(unit = "W") = constraint_force(floor, bc)*bc.b.v + constraint_torque(floor, bc)*bc.w;
equation
  bc.b.y = 0 "floor";
end Linkage;
"""
DUMBBELL = """
model Dumbbell "two point masses on a massless rigid rod, spinning in the plane"
  parameter Real m(unit = "kg") = 0.2;
  parameter Real L(unit = "m") = 0.5;
  parameter Real w(unit = "rad/s") = 6;
  PointMass a(m = m, r(start = {L/2, 0}), v(start = {0, w*L/2}));
  PointMass b(m = m, r(start = {-L/2, 0}), v(start = {0, -w*L/2}));
  output Real Fa[3] = constraint_force(rod, a);
  output Real Fb[3] = constraint_force(rod, b);
  output Real Ta[3] = constraint_torque(rod, a);
equation
  sqrt((a.x - b.x)^2 + (a.y - b.y)^2) = L "rod";
end Dumbbell;
"""
DISK_ODE = """
model RollingDiskODE "the rolling disk of RollingDisk in its one coordinate s (down the slope)"
  parameter Real m(unit = "kg") = 2;
  parameter Real R(unit = "m") = 0.3;
  parameter Real g(unit = "m/s2") = 9.81;
  parameter Real alpha(unit = "deg") = 30 "slope";
  parameter Real J(unit = "kg.m2") = 1 "inertia of an idle wheel";
  coordinate Real s(start = 0, speed = 0, unit = "m");
  coordinate Real turn(start = 0, speed = 0, unit = "deg") "an idle wheel, its angle in degrees";
equation
  kinetic = 3/4*m*der(s)^2 + 1/2*J*der(turn)^2;
  potential = -m*g*sin(alpha)*s;
end RollingDiskODE;
"""
