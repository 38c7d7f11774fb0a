build2/obj/common/render/integrator.o: common/render/integrator.c \
 common/render/integrator.h common/render/render_job.h \
 common/render/accel.h common/scene/scene.h common/base/vec.h \
 common/scene/motion.h common/scene/scene_limits.h common/scene/camera.h \
 common/scene/sampler.h common/base/rng.h common/scene/light.h \
 common/render/tile.h common/image/imgio.h \
 common/render/media_integrator.h common/scene/medium.h \
 common/render/surface.h common/render/texshade.h common/render/raydiff.h \
 common/scene/texture.h common/image/mip.h common/scene/material.h
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
common/render/media_integrator.h:
common/scene/medium.h:
common/render/surface.h:
common/render/texshade.h:
common/render/raydiff.h:
common/scene/texture.h:
common/image/mip.h:
common/scene/material.h:
