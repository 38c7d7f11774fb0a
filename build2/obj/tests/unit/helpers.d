build2/obj/tests/unit/helpers.o: tests/unit/helpers.c \
 tests/unit/helpers.h common/base/asset.h common/render/integrator.h \
 common/render/render_job.h common/render/accel.h common/scene/scene.h \
 common/base/vec.h common/scene/motion.h common/scene/scene_limits.h \
 common/scene/camera.h common/scene/sampler.h common/base/rng.h \
 common/scene/light.h common/render/tile.h common/image/imgio.h \
 common/base/log.h common/render/photon_map.h common/scene/medium.h \
 common/scene/scene_json.h
tests/unit/helpers.h:
common/base/asset.h:
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
common/image/imgio.h:
common/base/log.h:
common/render/photon_map.h:
common/scene/medium.h:
common/scene/scene_json.h:
