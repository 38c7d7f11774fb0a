build2/obj/common/scene/nvdb.o: common/scene/nvdb.c common/scene/nvdb.h \
 common/scene/grid.h common/scene/medium.h common/scene/scene_limits.h \
 common/base/vec.h common/base/bytes.h common/base/log.h
common/scene/nvdb.h:
common/scene/grid.h:
common/scene/medium.h:
common/scene/scene_limits.h:
common/base/vec.h:
common/base/bytes.h:
common/base/log.h:
