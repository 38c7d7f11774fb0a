build2/obj/common/scene/texture.o: common/scene/texture.c \
 common/scene/texture.h common/image/mip.h common/base/vec.h \
 common/scene/scene_limits.h
common/scene/texture.h:
common/image/mip.h:
common/base/vec.h:
common/scene/scene_limits.h:
