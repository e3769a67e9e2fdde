// A cylinder (radius 5, height 10) with an inclined penny crack (radius 1, normal tilted 30 degrees from z)
// at its centre (OpenCASCADE kernel: the disk is fragmented into the volume, so the mesh conforms to it).
SetFactory("OpenCASCADE");
R = 5; H = 10; a = 1; tilt = Pi / 6;
Cylinder(1) = {0, 0, -H / 2, 0, 0, H, R};
Disk(10) = {0, 0, 0, a};
Rotate {{0, 1, 0}, {0, 0, 0}, tilt} { Surface{10}; }
v() = BooleanFragments{ Volume{1}; Delete; }{ Surface{10}; Delete; };
// after the fragment: the crack is the surface inside the volume, the caps are the planes z = -H/2 and H/2
crack() = Surface In BoundingBox{-1.01, -1.01, -1.01, 1.01, 1.01, 1.01};
bottom() = Surface In BoundingBox{-R - 1, -R - 1, -H / 2 - 0.01, R + 1, R + 1, -H / 2 + 0.01};
top() = Surface In BoundingBox{-R - 1, -R - 1, H / 2 - 0.01, R + 1, R + 1, H / 2 + 0.01};
Physical Volume("cylinder") = {v()};
Physical Surface("crack") = {crack()};
Physical Surface("bottom") = {bottom()};
Physical Surface("top") = {top()};
