#!/usr/bin/env python3
"""A closed unit room with a ceiling light and an M x M grid of small boxes on the floor
(5 faces each): a scene of many small polygons, for measuring what hierarchical radiosity's
initial links between every pair of faces cost (bench/REPORT.md, "Many small polygons").

    python3 bench/make_clutter.py M OUT.obj     # writes OUT.obj and clutter.mtl beside it
"""
import sys
m = int(sys.argv[1]); out = sys.argv[2]
V=[]; F=[]
def quad(name, pts):
    base=len(V)+1
    V.extend(pts); F.append((name, [base, base+1, base+2, base+3]))
L=1.0
# closed room 0..1 cube, normals inward (front = CCW seen from inside)
quad('floor',  [(0,0,0),(0,0,L),(L,0,L),(L,0,0)])
quad('ceiling',[(0,L,0),(L,L,0),(L,L,L),(0,L,L)])
quad('back',   [(0,0,L),(0,L,L),(L,L,L),(L,0,L)])
quad('front',  [(0,0,0),(L,0,0),(L,L,0),(0,L,0)])
quad('left',   [(0,0,0),(0,L,0),(0,L,L),(0,0,L)])
quad('right',  [(L,0,0),(L,0,L),(L,L,L),(L,L,0)])
quad('light',  [(0.4,0.999,0.4),(0.6,0.999,0.4),(0.6,0.999,0.6),(0.4,0.999,0.6)])
# light faces down: CCW seen from below
s=0.5/m; h=0.05
for i in range(m):
  for j in range(m):
    x0=0.1+0.8*(i+0.25)/m; z0=0.1+0.8*(j+0.25)/m; x1=x0+s*0.8; z1=z0+s*0.8
    n='box'
    quad(n,[(x0,h,z0),(x0,h,z1),(x1,h,z1),(x1,h,z0)])  # top, up
    quad(n,[(x0,h,z0),(x1,h,z0),(x1,0,z0),(x0,0,z0)])  # -z
    quad(n,[(x1,0,z1),(x1,h,z1),(x0,h,z1),(x0,0,z1)])  # +z
    quad(n,[(x0,0,z1),(x0,h,z1),(x0,h,z0),(x0,0,z0)])  # -x
    quad(n,[(x1,h,z0),(x1,h,z1),(x1,0,z1),(x1,0,z0)])  # +x
with open(out,'w') as f:
  f.write('mtllib clutter.mtl\n')
  for v in V: f.write('v %g %g %g\n'%v)
  cur=None
  for name,idx in F:
    if name!=cur:
      f.write('o %s\nusemtl %s\n'%(name, 'light' if name=='light' else ('box' if name=='box' else 'wall'))); cur=name
    f.write('f %s\n'%' '.join(map(str,idx)))
with open(out.rsplit('/',1)[0]+'/clutter.mtl','w') as f:
  f.write('newmtl wall\nKd 0.6 0.6 0.6\nnewmtl box\nKd 0.5 0.4 0.3\nnewmtl light\nKd 0.5 0.5 0.5\nKe 20 20 20\n')
