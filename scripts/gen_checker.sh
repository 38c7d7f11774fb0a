#!/bin/sh
# Writes scenes/dof_motion/checker.obj: a 10 x 6 checker wall of emitting ("lit") and dark
# squares of 0.5 units at z = 4, facing -z (towards the camera; emitters are one-sided).
# Usage: sh scripts/gen_checker.sh > scenes/dof_motion/checker.obj
awk 'BEGIN{
  print "# A 10 x 6 checker wall of emitting and dark squares (0.5 units), facing -z at z = 4."
  print "# Generated for scenes/dof_motion by scripts/gen_checker.sh."
  print "mtllib checker.mtl"
  n=0
  for (c=0;c<2;c++){ print (c==0?"usemtl lit":"usemtl dark")
    for (i=0;i<10;i++) for (j=0;j<6;j++) if ((i+j)%2==c) {
      x0=-2.5+0.5*i; y0=0+0.5*j; x1=x0+0.5; y1=y0+0.5
      printf "v %g %g 4\nv %g %g 4\nv %g %g 4\nv %g %g 4\n", x0,y0, x1,y0, x1,y1, x0,y1
      printf "f %d %d %d %d\n", n+1, n+4, n+3, n+2; n+=4 } }
}'
