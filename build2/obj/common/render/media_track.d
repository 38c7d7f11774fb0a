build2/obj/common/render/media_track.o: common/render/media_track.c \
 common/render/media_track.h common/render/surface.h \
 common/render/accel.h common/scene/scene.h common/base/vec.h \
 common/scene/motion.h common/scene/scene_limits.h common/scene/light.h \
 common/scene/medium.h common/base/log.h common/base/rng.h \
 common/scene/grid.h
common/render/media_track.h:
common/render/surface.h:
common/render/accel.h:
common/scene/scene.h:
common/base/vec.h:
common/scene/motion.h:
common/scene/scene_limits.h:
common/scene/light.h:
common/scene/medium.h:
common/base/log.h:
common/base/rng.h:
common/scene/grid.h:
