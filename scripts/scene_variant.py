# Writes a copy of scenes/tiny moved and scaled in world space, p -> SCALE * p + T, for the
# scale and precision tests: vertices, camera, lamp transform, sphere, point light (its
# intensity times SCALE^2 so the image stays the same; the emitter is a radiance and keeps it).
# Usage: python3 scripts/scene_variant.py SRC_DIR DST_DIR SCALE TX TY TZ
import json, os, shutil, sys
src, dst, s = sys.argv[1], sys.argv[2], float(sys.argv[3])
t = [float(x) for x in sys.argv[4:7]]
os.makedirs(dst, exist_ok=True)
shutil.copy(os.path.join(src, 'tiny.mtl'), dst)
def pt(p): return [s * p[i] + t[i] for i in range(3)]
for name, move in (('tiny.obj', True), ('lamp.obj', False)):
    out = []
    for line in open(os.path.join(src, name)):
        f = line.split()
        if f and f[0] == 'v':
            v = [float(x) for x in f[1:4]]
            v = pt(v) if move else [s * x for x in v]
            line = 'v %.17g %.17g %.17g\n' % tuple(v)
        out.append(line)
    open(os.path.join(dst, name), 'w').writelines(out)
sc = json.load(open(os.path.join(src, 'tiny.json')))
c = sc['camera']
c['position'] = pt(c['position']); c['look_at'] = pt(c['look_at'])
for o in sc['objects']:
    if 'transform' in o: o['transform']['translate'] = pt(o['transform']['translate'])
    if o['type'] == 'sphere': o['center'] = pt(o['center']); o['radius'] *= s
for l in sc['lights']:
    l['position'] = pt(l['position']); l['intensity'] = [x * s * s for x in l['intensity']]
json.dump(sc, open(os.path.join(dst, 'tiny.json'), 'w'), indent=1)
