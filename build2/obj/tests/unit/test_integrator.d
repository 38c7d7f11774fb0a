build2/obj/tests/unit/test_integrator.o: tests/unit/test_integrator.c \
 common/render/integrator.h common/render/render_job.h \
 common/render/accel.h common/scene/scene.h common/base/vec.h \
 common/scene/motion.h common/scene/scene_limits.h common/scene/camera.h \
 common/scene/sampler.h common/base/rng.h common/scene/light.h \
 common/render/tile.h common/image/imgio.h common/base/log.h \
 tests/unit/helpers.h common/base/asset.h
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
tests/unit/helpers.h:
common/base/asset.h:
