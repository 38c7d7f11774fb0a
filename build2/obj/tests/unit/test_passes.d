build2/obj/tests/unit/test_passes.o: tests/unit/test_passes.c \
 common/base/log.h common/base/rng.h master/opts.h master/photons.h \
 common/base/asset.h master/opts.h common/scene/scene.h common/base/vec.h \
 common/scene/motion.h common/scene/scene_limits.h \
 common/render/integrator.h common/render/render_job.h \
 common/render/accel.h common/scene/camera.h common/scene/sampler.h \
 common/scene/light.h common/render/tile.h common/image/imgio.h \
 common/render/passes.h common/scene/medium.h common/render/photon_map.h \
 tests/unit/helpers.h
common/base/log.h:
common/base/rng.h:
master/opts.h:
master/photons.h:
common/base/asset.h:
master/opts.h:
common/scene/scene.h:
common/base/vec.h:
common/scene/motion.h:
common/scene/scene_limits.h:
common/render/integrator.h:
common/render/render_job.h:
common/render/accel.h:
common/scene/camera.h:
common/scene/sampler.h:
common/scene/light.h:
common/render/tile.h:
common/image/imgio.h:
common/render/passes.h:
common/scene/medium.h:
common/render/photon_map.h:
tests/unit/helpers.h:
