build2/obj/tests/unit/test_nvdb.o: tests/unit/test_nvdb.c \
 common/render/integrator.h common/render/render_job.h \
 common/render/accel.h common/scene/scene.h common/base/vec.h \
 common/scene/motion.h common/scene/scene_limits.h common/scene/camera.h \
 common/scene/sampler.h common/base/rng.h common/scene/light.h \
 common/render/tile.h common/image/imgio.h common/base/log.h \
 common/render/media_integrator.h common/scene/medium.h \
 common/scene/grid.h common/scene/nvdb.h common/scene/scene_json.h \
 common/base/asset.h tests/unit/helpers.h \
 tests/unit/../tools/nvdb_values.h
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
common/scene/grid.h:
common/scene/nvdb.h:
common/scene/scene_json.h:
common/base/asset.h:
tests/unit/helpers.h:
tests/unit/../tools/nvdb_values.h:
