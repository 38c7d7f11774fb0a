build2/obj/common/render/texshade.o: common/render/texshade.c \
 common/render/texshade.h common/render/raydiff.h common/scene/camera.h \
 common/scene/sampler.h common/base/rng.h common/scene/scene.h \
 common/base/vec.h common/scene/motion.h common/scene/scene_limits.h \
 common/scene/texture.h common/image/mip.h common/render/render_job.h \
 common/render/accel.h common/scene/light.h common/scene/material.h \
 common/base/log.h
common/render/texshade.h:
common/render/raydiff.h:
common/scene/camera.h:
common/scene/sampler.h:
common/base/rng.h:
common/scene/scene.h:
common/base/vec.h:
common/scene/motion.h:
common/scene/scene_limits.h:
common/scene/texture.h:
common/image/mip.h:
common/render/render_job.h:
common/render/accel.h:
common/scene/light.h:
common/scene/material.h:
common/base/log.h:
