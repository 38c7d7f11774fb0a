build2/obj/tests/unit/test_texture.o: tests/unit/test_texture.c \
 common/image/image_load.h common/base/asset.h common/image/mip.h \
 common/base/vec.h common/image/imgio.h common/render/integrator.h \
 common/render/render_job.h common/render/accel.h common/scene/scene.h \
 common/scene/motion.h common/scene/scene_limits.h common/scene/camera.h \
 common/scene/sampler.h common/base/rng.h common/scene/light.h \
 common/render/tile.h common/base/log.h common/scene/material.h \
 common/render/raydiff.h common/scene/texture.h tests/unit/helpers.h \
 common/scene/scene_json.h common/render/texshade.h
common/image/image_load.h:
common/base/asset.h:
common/image/mip.h:
common/base/vec.h:
common/image/imgio.h:
common/render/integrator.h:
common/render/render_job.h:
common/render/accel.h:
common/scene/scene.h:
common/scene/motion.h:
common/scene/scene_limits.h:
common/scene/camera.h:
common/scene/sampler.h:
common/base/rng.h:
common/scene/light.h:
common/render/tile.h:
common/base/log.h:
common/scene/material.h:
common/render/raydiff.h:
common/scene/texture.h:
tests/unit/helpers.h:
common/scene/scene_json.h:
common/render/texshade.h:
