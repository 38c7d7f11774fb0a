build2/obj/common/image/imgio.o: common/image/imgio.c \
 common/image/imgio.h common/base/bytes.h common/base/log.h
common/image/imgio.h:
common/base/bytes.h:
common/base/log.h:
