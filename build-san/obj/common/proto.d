build-san/obj/common/proto.o: common/proto.c common/proto.h common/blob.h \
 common/tile.h common/imgio.h common/scene.h common/vec.h common/log.h
common/proto.h:
common/blob.h:
common/tile.h:
common/imgio.h:
common/scene.h:
common/vec.h:
common/log.h:
