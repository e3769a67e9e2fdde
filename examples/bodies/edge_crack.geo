// A strip of width b = 1 and height 4 with an edge crack of length a = 0.3 from its left side at mid-height
// (gmsh built-in kernel). The left side is split at the crack's mouth so that the mouth is a mesh node.
b = 1; H = 4; a = 0.3; h = 0.1;
Point(1) = {0, 0, 0, h}; Point(2) = {b, 0, 0, h}; Point(3) = {b, H, 0, h}; Point(4) = {0, H, 0, h};
Point(5) = {0, H / 2, 0, h}; Point(6) = {a, H / 2, 0, h};
Line(1) = {1, 2}; Line(2) = {2, 3}; Line(3) = {3, 4}; Line(4) = {4, 5}; Line(5) = {5, 1};
Curve Loop(1) = {1, 2, 3, 4, 5};
Plane Surface(1) = {1};
Line(6) = {5, 6};                  // the crack, from its mouth to its tip: its "+" face is the upper one
Line{6} In Surface{1};             // embedded: the mesh conforms to it
Physical Surface("strip") = {1};
Physical Curve("bottom") = {1};
Physical Curve("top") = {3};
Physical Curve("crack") = {6};
