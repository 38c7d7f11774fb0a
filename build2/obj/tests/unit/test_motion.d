build2/obj/tests/unit/test_motion.o: tests/unit/test_motion.c \
 common/render/integrator.h common/render/render_job.h \
 common/render/accel.h common/scene/scene.h common/base/vec.h \
 common/scene/motion.h common/scene/scene_limits.h common/scene/camera.h \
 common/scene/sampler.h common/base/rng.h common/scene/light.h \
 common/render/tile.h common/image/imgio.h common/base/log.h \
 common/scene/scene_json.h common/base/asset.h common/scene/texture.h \
 common/image/mip.h tests/unit/helpers.h
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
common/scene/scene_json.h:
common/base/asset.h:
common/scene/texture.h:
common/image/mip.h:
tests/unit/helpers.h:
