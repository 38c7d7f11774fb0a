build2/obj/tests/tools/texbench.o: tests/tools/texbench.c \
 common/base/log.h common/image/mip.h common/base/vec.h \
 common/scene/texture.h common/scene/scene_limits.h
common/base/log.h:
common/image/mip.h:
common/base/vec.h:
common/scene/texture.h:
common/scene/scene_limits.h:
