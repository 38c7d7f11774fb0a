build2/obj/worker/worker.o: worker/worker.c worker/worker.h \
 common/base/asset.h common/wire/blob.h common/image/imgio.h \
 common/render/integrator.h common/render/render_job.h \
 common/render/accel.h common/scene/scene.h common/base/vec.h \
 common/scene/motion.h common/scene/scene_limits.h common/scene/camera.h \
 common/scene/sampler.h common/base/rng.h common/scene/light.h \
 common/render/tile.h common/base/log.h common/scene/medium.h \
 common/wire/net.h common/wire/proto.h common/render/photon_map.h \
 common/scene/scene_json.h
worker/worker.h:
common/base/asset.h:
common/wire/blob.h:
common/image/imgio.h:
common/render/integrator.h:
common/render/render_job.h:
common/render/accel.h:
common/scene/scene.h:
common/base/vec.h:
common/scene/motion.h:
common/scene/scene_limits.h:
common/scene/camera.h:
common/scene/sampler.h:
common/base/rng.h:
common/scene/light.h:
common/render/tile.h:
common/base/log.h:
common/scene/medium.h:
common/wire/net.h:
common/wire/proto.h:
common/render/photon_map.h:
common/scene/scene_json.h:
