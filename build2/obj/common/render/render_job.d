build2/obj/common/render/render_job.o: common/render/render_job.c \
 common/render/render_job.h common/render/accel.h common/scene/scene.h \
 common/base/vec.h common/scene/motion.h common/scene/scene_limits.h \
 common/scene/camera.h common/scene/sampler.h common/base/rng.h \
 common/scene/light.h common/base/log.h common/image/mip.h \
 common/render/media_track.h common/render/surface.h \
 common/scene/medium.h common/render/photon_map.h common/scene/texture.h
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
common/base/log.h:
common/image/mip.h:
common/render/media_track.h:
common/render/surface.h:
common/scene/medium.h:
common/render/photon_map.h:
common/scene/texture.h:
