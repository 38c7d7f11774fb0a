build2/obj/tests/unit/test_medium.o: tests/unit/test_medium.c \
 common/wire/blob.h common/render/integrator.h common/render/render_job.h \
 common/render/accel.h common/scene/scene.h common/base/vec.h \
 common/scene/motion.h common/scene/scene_limits.h common/scene/camera.h \
 common/scene/sampler.h common/base/rng.h common/scene/light.h \
 common/render/tile.h common/image/imgio.h common/base/log.h \
 common/render/media_integrator.h common/scene/medium.h \
 common/render/photon_map.h common/render/photon_trace.h \
 common/render/media_track.h common/render/surface.h common/scene/grid.h \
 common/scene/scene_json.h common/base/asset.h tests/unit/helpers.h
common/wire/blob.h:
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
common/render/media_integrator.h:
common/scene/medium.h:
common/render/photon_map.h:
common/render/photon_trace.h:
common/render/media_track.h:
common/render/surface.h:
common/scene/grid.h:
common/scene/scene_json.h:
common/base/asset.h:
tests/unit/helpers.h:
