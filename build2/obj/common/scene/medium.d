build2/obj/common/scene/medium.o: common/scene/medium.c \
 common/scene/medium.h common/scene/scene_limits.h common/base/vec.h \
 common/base/log.h
common/scene/medium.h:
common/scene/scene_limits.h:
common/base/vec.h:
common/base/log.h:
