build2/obj/common/render/photon_map.o: common/render/photon_map.c \
 common/render/photon_map.h common/scene/medium.h \
 common/scene/scene_limits.h common/base/vec.h common/scene/scene.h \
 common/scene/motion.h common/base/bytes.h common/base/log.h
common/render/photon_map.h:
common/scene/medium.h:
common/scene/scene_limits.h:
common/base/vec.h:
common/scene/scene.h:
common/scene/motion.h:
common/base/bytes.h:
common/base/log.h:
