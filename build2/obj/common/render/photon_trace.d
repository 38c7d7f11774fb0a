build2/obj/common/render/photon_trace.o: common/render/photon_trace.c \
 common/render/photon_trace.h common/base/log.h common/base/rng.h \
 common/render/media_track.h common/render/surface.h \
 common/render/accel.h common/scene/scene.h common/base/vec.h \
 common/scene/motion.h common/scene/scene_limits.h common/scene/light.h \
 common/scene/medium.h common/render/photon_map.h \
 common/render/render_job.h common/scene/camera.h common/scene/sampler.h \
 common/scene/grid.h common/scene/material.h
common/render/photon_trace.h:
common/base/log.h:
common/base/rng.h:
common/render/media_track.h:
common/render/surface.h:
common/render/accel.h:
common/scene/scene.h:
common/base/vec.h:
common/scene/motion.h:
common/scene/scene_limits.h:
common/scene/light.h:
common/scene/medium.h:
common/render/photon_map.h:
common/render/render_job.h:
common/scene/camera.h:
common/scene/sampler.h:
common/scene/grid.h:
common/scene/material.h:
