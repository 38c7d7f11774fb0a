build-san/obj/common/net.o: common/net.c common/net.h common/proto.h \
 common/blob.h common/tile.h common/imgio.h common/scene.h common/vec.h \
 common/log.h
common/net.h:
common/proto.h:
common/blob.h:
common/tile.h:
common/imgio.h:
common/scene.h:
common/vec.h:
common/log.h:
